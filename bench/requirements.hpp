#pragma once
// The thresholds a bench's figures are held to when it runs as a test (bench/CMakeLists.txt, labelled
// "bench"): `--require NAME<=VALUE` or `--require NAME>=VALUE` on the command line. The bench reports each
// figure through report(); exit_status() is 1 if a required figure is beyond its threshold or was never
// reported, so an accuracy regression fails the test command.
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace gearpulse::bench {

class Requirements {
 public:
  // Takes the --require pairs out of argv (argc shrinks); false after printing why for a malformed one.
  bool parse(int& argc, char** argv) {
    int kept = 1;
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      if (a != "--require") {
        argv[kept++] = argv[i];
        continue;
      }
      if (i + 1 >= argc || !add(argv[++i])) {
        std::fprintf(stderr, "--require wants NAME<=VALUE or NAME>=VALUE\n");
        return false;
      }
    }
    argc = kept;
    return true;
  }

  // Prints "figure NAME = VALUE" and, if a threshold names it, whether it holds.
  void report(const std::string& name, double value) {
    std::printf("figure %s = %.6g", name.c_str(), value);
    for (Bound& b : bounds_) {
      if (b.name != name) continue;
      b.seen = true;
      const bool holds = b.at_most ? value <= b.value : value >= b.value;
      b.failed = b.failed || !holds;
      std::printf(" (required %s %g: %s)", b.at_most ? "<=" : ">=", b.value, holds ? "ok" : "FAILED");
    }
    std::printf("\n");
  }

  [[nodiscard]] int exit_status() const {
    int status = 0;
    for (const Bound& b : bounds_) {
      if (!b.seen) std::printf("figure %s required but not reported: FAILED\n", b.name.c_str());
      if (!b.seen || b.failed) status = 1;
    }
    return status;
  }

 private:
  struct Bound {
    std::string name;
    bool at_most = true;
    double value = 0.0;
    bool seen = false;
    bool failed = false;
  };

  bool add(const std::string& spec) {
    for (const char* op : {"<=", ">="}) {
      const std::size_t at = spec.find(op);
      if (at == std::string::npos || at == 0) continue;
      char* end = nullptr;
      const double v = std::strtod(spec.c_str() + at + 2, &end);
      if (end == spec.c_str() + at + 2 || *end != '\0') return false;
      bounds_.push_back({spec.substr(0, at), op[0] == '<', v});
      return true;
    }
    return false;
  }

  std::vector<Bound> bounds_;
};

}  // namespace gearpulse::bench
