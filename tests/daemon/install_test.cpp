// The install the README gives (`cmake -DCMAKE_INSTALL_PREFIX=/usr`, `cmake --install`): the service unit
// must find the configuration and the binary where the install puts them. Checked on the install script a
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

}  // namespace

TEST_CASE("install: with the README's prefix the unit finds its configuration and binary") {
  TempDir dir;
  const std::string build = (dir / "build").string();
  const ShellResult configure = run_shell("cmake -S '" + std::string(GEARPULSE_SOURCE_DIR) + "' -B '" +
                                          build + "' -DCMAKE_INSTALL_PREFIX=/usr -DGEARPULSE_BENCH=OFF > '" +
                                          (dir / "log").string() + "' 2>&1");
  INFO(slurp(dir / "log"));
  REQUIRE(configure.status == 0);
  const std::string top = slurp(dir / "build" / "cmake_install.cmake");
  const std::string daemon = slurp(dir / "build" / "daemon" / "cmake_install.cmake");
  const std::string unit =
      slurp(std::filesystem::path(GEARPULSE_SOURCE_DIR) / "systemd" / "gearpulsed.service");

  // The unit reads /etc/gearpulse/gearpulse.toml; the install must put the default configuration there,
  // not under the prefix (/usr/etc).
  REQUIRE(unit.find("ExecStart=gearpulsed --config /etc/gearpulse/gearpulse.toml") != std::string::npos);
  CHECK(top.find("file(INSTALL DESTINATION \"/etc/gearpulse\"") != std::string::npos);
  CHECK(top.find("/usr/etc") == std::string::npos);
  // The unit names the binary bare: systemd looks it up in /usr/sbin among its fixed paths.
  CHECK(daemon.find("DESTINATION \"${CMAKE_INSTALL_PREFIX}/sbin\"") != std::string::npos);
  CHECK(top.find("DESTINATION \"${CMAKE_INSTALL_PREFIX}/lib/systemd/system\"") != std::string::npos);
}
