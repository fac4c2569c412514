// --version of every program, and the installed offline tool without the development commands.
#include <filesystem>
#include <string>

#include <catch2/catch.hpp>

#include "gearpulse_version.hpp"
#include "tests/test_util.hpp"

namespace {

const std::string kBuild = GEARPULSE_BINARY_DIR;

}  // namespace

TEST_CASE("version: every program prints its name and the project's version, exit 0") {
  for (const char* program :
       {"tools/gearpulse", "tools/gearpulsectl", "daemon/gearpulsed", "tools/gearpulse-devtools"}) {
    const std::string path = kBuild + "/" + program;
    if (!std::filesystem::exists(path)) {
      WARN("GEARPULSE_SKIP: " << path << " is not built");
      continue;
    }
    const gearpulse::test::ShellResult r = gearpulse::test::run_shell(path + " --version 2>&1");
    const std::string name = std::filesystem::path(program).filename().string();
    INFO(path << ": " << r.out);
    CHECK(r.status == 0);
    CHECK(r.out == name + " " + gearpulse::kVersion + "\n");
  }
}

TEST_CASE("version: gearpulse carries fit, replay and track, not simulate or feed") {
  const std::string cli = kBuild + "/tools/gearpulse";
  for (const char* command : {"simulate --out /nonexistent", "feed a b"}) {
    const gearpulse::test::ShellResult r = gearpulse::test::run_shell(cli + " " + command + " 2>&1");
    INFO(command << ": " << r.out);
    CHECK(r.status == 2);
    CHECK(r.out.find("unknown command") != std::string::npos);
  }
  const gearpulse::test::ShellResult help = gearpulse::test::run_shell(cli + " --help 2>&1");
  for (const char* command : {"fit", "replay", "track"})
    CHECK(help.out.find(command) != std::string::npos);
}
