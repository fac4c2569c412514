// The install layout: the service unit names the daemon and its configuration by the absolute paths the
// install puts them at, for the package's prefix (/usr) and for the default one. Checked on the files a
// configure-only run writes (no build needed).
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "tests/test_util.hpp"

using gearpulse::test::run_shell;
using gearpulse::test::ShellResult;
using gearpulse::test::TempDir;

namespace {

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

struct Configured {
  std::string top, daemon, unit, conffiles;
};

Configured configure(const TempDir& dir, const std::string& options) {
  const std::string build = (dir / "build").string();
  const ShellResult configure =
      run_shell("cmake -S '" + std::string(GEARPULSE_SOURCE_DIR) + "' -B '" + build + "' " + options +
                " -DGEARPULSE_BENCH=OFF > '" + (dir / "log").string() + "' 2>&1");
  INFO(slurp(dir / "log"));
  REQUIRE(configure.status == 0);
  return {slurp(dir / "build" / "cmake_install.cmake"),
          slurp(dir / "build" / "daemon" / "cmake_install.cmake"),
          slurp(dir / "build" / "systemd" / "gearpulsed.service"),
          slurp(dir / "build" / "packaging" / "conffiles")};
}

}  // namespace

TEST_CASE("install: with the package's prefix the unit runs /usr/sbin/gearpulsed on /etc's configuration") {
  TempDir dir;
  const Configured c = configure(dir, "-DCMAKE_INSTALL_PREFIX=/usr");
  INFO(c.unit);
  CHECK(c.unit.find("\nExecStart=/usr/sbin/gearpulsed --config /etc/gearpulse/gearpulse.toml\n") !=
        std::string::npos);
  CHECK(c.unit.find("@GEARPULSE") == std::string::npos);  // every path substituted
  // The configuration goes to /etc, not under the prefix (/usr/etc), and is the package's conffile.
  CHECK(c.top.find("file(INSTALL DESTINATION \"/etc/gearpulse\"") != std::string::npos);
  CHECK(c.top.find("/usr/etc") == std::string::npos);
  CHECK(c.conffiles == "/etc/gearpulse/gearpulse.toml\n");
  CHECK(c.daemon.find("DESTINATION \"${CMAKE_INSTALL_PREFIX}/sbin\"") != std::string::npos);
  CHECK(c.top.find("DESTINATION \"${CMAKE_INSTALL_PREFIX}/lib/systemd/system\"") != std::string::npos);
}

TEST_CASE("install: with the default prefix the unit names the binary and configuration under it") {
  TempDir dir;
  const Configured c = configure(dir, "-DCMAKE_INSTALL_PREFIX=/usr/local");
  INFO(c.unit);
  CHECK(c.unit.find(
            "\nExecStart=/usr/local/sbin/gearpulsed --config /usr/local/etc/gearpulse/gearpulse.toml\n") !=
        std::string::npos);
  CHECK(c.top.find("file(INSTALL DESTINATION \"/usr/local/etc/gearpulse\"") != std::string::npos);
}
