#pragma once
// What the tests of `gearpulse fit` and `gearpulse replay` (cli_test.cpp, cli_errors_test.cpp,
// cli_replay_test.cpp) share: the built binary run with its output captured, and the simulated logs and
// fitted model they run it on.
#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <catch2/catch.hpp>

#include "core/sample_io.hpp"
#include "tests/test_util.hpp"
#include "tools/sim/vehicle_sim.hpp"

namespace gearpulse::test::cli {

inline const std::string kCli = GEARPULSE_BINARY_DIR "/tools/gearpulse";

inline std::string slurp(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

inline void write(const std::string& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary);
  out << text;
}

struct Result {
  int status = -1;
  std::string out, err;
};

// Runs the CLI with `args` (already quoted as needed); stdout and stderr captured apart.
inline Result run(const TempDir& dir, const std::string& args) {
  const std::string err_path = (dir / "stderr.txt").string();
  const gearpulse::test::ShellResult s = gearpulse::test::run_shell(kCli + " " + args + " 2>" + err_path);
  return {s.status, s.out, slurp(err_path)};
}

inline std::size_t lines(const std::string& text) {
  std::size_t n = 0;
  for (char c : text)
    n += c == '\n';
  return n;
}

// The samples gearpulse's reader takes from `path`, as `replay` reads them.
inline gearpulse::SampleLog read_log(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return gearpulse::read_samples(in, path);
}

// A simulated 20-minute drive of an Etios-like hatchback at 1 Hz, as a generic CSV.
inline std::string simulated_log(const TempDir& dir, std::uint64_t seed, double outage_from = -1.0) {
  using namespace gearpulse::sim;
  const auto obs = simulate_observations(vehicle_preset("hatch-5"), DrivingStyle::kMixed, 1200.0, 1, seed,
                                         {.seed = seed + 100});
  auto samples = to_samples(obs);
  if (outage_from >= 0.0) {
    for (auto& s : samples)
      if (s.t >= outage_from && s.t < outage_from + 60.0) s.speed = gearpulse::kMissing;
  }
  const std::string path = (dir / ("drive" + std::to_string(seed) + ".csv")).string();
  std::ofstream out(path, std::ios::binary);
  gearpulse::write_samples(out, samples);
  return path;
}

// Fits the model the replay tests read, from the simulated drive of seed 23; returns its path.
inline std::string fitted_model(const TempDir& dir) {
  const std::string train = simulated_log(dir, 23);
  const std::string model = (dir / "model.json").string();
  REQUIRE(run(dir, "fit --out " + model + " " + train).status == 0);
  return model;
}

// The comma-separated cells of one output row.
inline std::vector<std::string> cells_of(const std::string& line) {
  std::vector<std::string> cells;
  std::stringstream ls(line);
  for (std::string cell; std::getline(ls, cell, ',');)
    cells.push_back(cell);
  return cells;
}

// What `replay --model MODEL LOG` printed: the run, and the cells of every row under the header of
// docs/interfaces.md (t,speed,gear,source), each row checked to have four.
struct Replay {
  Result result;
  std::vector<std::vector<std::string>> rows;
};

inline Replay replay(const TempDir& dir, const std::string& model, const std::string& log) {
  Replay r{run(dir, "replay --model " + model + " " + log), {}};
  REQUIRE(r.result.status == 0);
  std::istringstream out(r.result.out);
  std::string line;
  std::getline(out, line);
  REQUIRE(line == "t,speed,gear,source");
  while (std::getline(out, line)) {
    r.rows.push_back(cells_of(line));
    REQUIRE(r.rows.back().size() == 4);
  }
  return r;
}

}  // namespace gearpulse::test::cli
