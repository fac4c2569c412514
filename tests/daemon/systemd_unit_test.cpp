// The service unit's contract with gearpulsed, checked on the unit this build installs
// (build/systemd/gearpulsed.service): its commands run as written, with the built binary in place of the
// installed one and a test's configuration in place of /etc's, and the exit statuses it names
// (RestartPreventExitStatus=, SuccessExitStatus=) are those gearpulsed returns in each case, judged as
// systemd judges them (systemd.service(5)). A change of the unit or of the binary that parts them fails
// here. systemd-analyze verify checks the unit offline (no running systemd needed).
#include <signal.h>

#include <chrono>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <catch2/catch.hpp>

#include "tests/test_util.hpp"

using gearpulse::test::LineClient;
using gearpulse::test::Process;
using gearpulse::test::read_text;
using gearpulse::test::run_shell;
using gearpulse::test::TempDir;
using gearpulse::test::write_text;

namespace {

const std::string kUnitPath = GEARPULSE_BINARY_DIR "/systemd/gearpulsed.service";
const std::string kDaemon = GEARPULSE_BINARY_DIR "/daemon/gearpulsed";

// The [Service] section: every value of each key, in order (ExecStartPre= and the like may repeat).
std::map<std::string, std::vector<std::string>> service_section(const std::string& unit) {
  std::map<std::string, std::vector<std::string>> keys;
  std::istringstream in(unit);
  std::string line, section;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || line[0] == ';') continue;
    if (line[0] == '[') {
      section = line;
      continue;
    }
    const std::size_t eq = line.find('=');
    if (section == "[Service]" && eq != std::string::npos)
      keys[line.substr(0, eq)].push_back(line.substr(eq + 1));
  }
  return keys;
}

std::vector<std::string> words(const std::string& text) {
  std::istringstream in(text);
  std::vector<std::string> out;
  for (std::string w; in >> w;)
    out.push_back(w);
  return out;
}

// The exit statuses a key lists ("2 3 SIGKILL": the numbers; signal names are not exit statuses).
std::set<int> statuses(const std::map<std::string, std::vector<std::string>>& keys, const std::string& key) {
  std::set<int> out;
  if (const auto it = keys.find(key); it != keys.end())
    for (const std::string& value : it->second)
      for (const std::string& w : words(value))
        if (w.find_first_not_of("0123456789") == std::string::npos) out.insert(std::stoi(w));
  return out;
}

struct Unit {
  std::string text;
  std::map<std::string, std::vector<std::string>> service;
  std::string installed_daemon;  // the path the unit runs gearpulsed at
  std::string installed_config;  // the configuration it names
};

Unit installed_unit() {
  Unit u;
  u.text = read_text(kUnitPath);
  REQUIRE_FALSE(u.text.empty());
  u.service = service_section(u.text);
  REQUIRE(u.service["ExecStart"].size() == 1);
  const std::vector<std::string> start = words(u.service["ExecStart"][0]);
  REQUIRE(start.size() >= 3);
  REQUIRE(std::filesystem::path(start[0]).filename() == "gearpulsed");
  REQUIRE(start[1] == "--config");
  u.installed_daemon = start[0];
  u.installed_config = start[2];
  return u;
}

// A command of the unit as systemd would run it, here: the built daemon for the installed one and
// `config` for the installed configuration; every other word as written. The unit quotes nothing
// (checked), so its words are split at blanks as systemd splits them.
std::vector<std::string> as_run_here(const Unit& u, const std::string& command, const std::string& config) {
  REQUIRE(command.find_first_of("\"'\\$%") == std::string::npos);
  std::vector<std::string> argv = words(command);
  REQUIRE_FALSE(argv.empty());
  for (std::string& w : argv) {
    if (w == u.installed_daemon) w = kDaemon;
    if (w == u.installed_config) w = config;
  }
  REQUIRE(argv[0] == kDaemon);
  return argv;
}

// Runs argv to its end; its exit status and what it wrote (stdout and stderr).
std::pair<int, std::string> run_to_end(const std::vector<std::string>& argv, const TempDir& dir,
                                       const std::string& name) {
  Process p(argv, dir / name);
  const auto status = p.wait(20'000);
  REQUIRE(status.has_value());
  return {*status, read_text(dir / name)};
}

std::string good_config(const TempDir& dir) {
  return "[audio]\ndevice = \"gearpulse_test_no_such_pcm\"\n"
         "[gps]\nhost = \"127.0.0.1\"\nport = " +
         std::to_string(gearpulse::test::free_port()) +
         "\n[output]\nkind = \"none\"\n[model]\nstate_dir = \"" + (dir / "state").string() +
         "\"\n[control]\nsocket = \"" + (dir / "ctl.sock").string() + "\"\n[log]\nlevel = \"info\"\n";
}

// Configurations the daemon must refuse, each with the line its message names.
struct BadConfig {
  std::string text;
  int line;
};
const std::vector<BadConfig>& bad_configs() {
  static const std::vector<BadConfig> configs = {
      {"[model]\nstate_dir = \"/tmp\"\nretrain_interval = -5\n", 3},  // a value out of range
      {"[audio]\nrate = 48000\n[output\nkind = \"none\"\n", 3},       // not TOML
      {"[gps]\nport = 2947\nspeed = 3\n", 3},                         // a key gearpulsed does not know
  };
  return configs;
}

}  // namespace

TEST_CASE("systemd unit: a bad config fails the start with a status the unit does not restart on") {
  Unit u = installed_unit();
  const auto prevent = statuses(u.service, "RestartPreventExitStatus");
  const auto success = statuses(u.service, "SuccessExitStatus");
  INFO(u.text);
  REQUIRE(u.service["Restart"] == std::vector<std::string>{"on-failure"});
  TempDir dir;
  const std::string config = (dir / "gearpulse.toml").string();
  for (std::size_t i = 0; i < bad_configs().size(); ++i) {
    const BadConfig& bad = bad_configs()[i];
    write_text(config, bad.text);
    INFO(bad.text);
    // systemd applies RestartPreventExitStatus= to the main process only: an ExecStartPre= that fails
    // (unless its failure is ignored, "-") has the unit restarted every RestartSec, for ever.
    for (const std::string& command : u.service["ExecStartPre"]) {
      if (command.starts_with("-")) continue;
      const auto pre = as_run_here(u, command.substr(command.find_first_not_of("@:+!")), config);
      const auto [status, out] = run_to_end(pre, dir, "pre" + std::to_string(i) + ".txt");
      INFO("ExecStartPre=" << command << " -> status " << status << ": " << out);
      CHECK(status == 0);
    }
    // The daemon refuses it before it opens anything, with a status that stops the restarts.
    const auto start = as_run_here(u, u.service["ExecStart"][0], config);
    const auto [status, out] = run_to_end(start, dir, "start" + std::to_string(i) + ".txt");
    INFO("ExecStart -> status " << status << ": " << out);
    CHECK(status != 0);
    CHECK(prevent.count(status) == 1);
    CHECK(success.count(status) == 0);
    CHECK(out.find(config + ":" + std::to_string(bad.line) + ":") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir / "ctl.sock"));
  }
}

TEST_CASE("systemd unit: ExecStart as written ends in 0 on SIGTERM and restartably on a fault") {
  Unit u = installed_unit();
  const auto prevent = statuses(u.service, "RestartPreventExitStatus");
  const auto success = statuses(u.service, "SuccessExitStatus");
  INFO(u.text);
  TempDir dir;
  const std::string config = (dir / "gearpulse.toml").string();
  const auto start = as_run_here(u, u.service["ExecStart"][0], config);

  SECTION("SIGTERM (systemctl stop): a clean exit, which Restart=on-failure does not restart") {
    write_text(config, good_config(dir));
    Process daemon(start, dir / "run.txt");
    const bool up = gearpulse::test::wait_for(
        [&] {
          LineClient c((dir / "ctl.sock").string());
          return c.connected() && c.send_all("{\"v\":1,\"cmd\":\"status\"}\n") && c.read_line().has_value();
        },
        std::chrono::seconds(15));
    INFO(read_text(dir / "run.txt"));
    REQUIRE(up);
    daemon.signal(SIGTERM);
    const auto status = daemon.wait(20'000);
    REQUIRE(status.has_value());
    CHECK((*status == 0 || success.count(*status) == 1));
  }
  SECTION("a fault of its surroundings (the control socket cannot be made): a status it restarts on") {
    // A transient fault (a runtime directory not there yet) may be gone at the next start: the status
    // must be a failure the unit neither takes for success nor exempts from Restart=on-failure.
    std::string text = good_config(dir);
    const std::string sock = (dir / "ctl.sock").string();
    text.replace(text.find(sock), sock.size(), "/dev/null/ctl.sock");
    write_text(config, text);
    const auto [status, out] = run_to_end(start, dir, "fault.txt");
    INFO(out);
    CHECK(status != 0);
    CHECK(status < 128);  // an exit, not a crash
    CHECK(prevent.count(status) == 0);
    CHECK(success.count(status) == 0);
  }
}

TEST_CASE("systemd unit: systemd-analyze verify finds nothing to say about the installed unit") {
  if (run_shell("command -v systemd-analyze >/dev/null 2>&1").status != 0)
    GEARPULSE_SKIP_TEST("systemd-analyze is not installed");
  Unit u = installed_unit();
  TempDir dir;
  // The same unit with the built daemon where it will be installed (verify checks the commands exist).
  std::string text = u.text;
  for (std::size_t at; (at = text.find(u.installed_daemon)) != std::string::npos;)
    text.replace(at, u.installed_daemon.size(), kDaemon);
  write_text(dir / "gearpulsed.service", text);
  // Everything it says (a value it cannot parse is only a warning, status 0) is a finding. The man pages
  // of Documentation= are the package's, not installed here.
  const auto r =
      run_shell("systemd-analyze verify --man=no '" + (dir / "gearpulsed.service").string() + "' 2>&1");
  INFO(r.out);
  CHECK(r.status == 0);
  CHECK(r.out.empty());
}

// systemd as PID 1 of a PID and mount namespace of its own, with only this unit (systemd_namespace.sh):
// the unit as systemd runs it, sandbox and all, on the release binary.
TEST_CASE("systemd unit: under systemd in a namespace it starts, is restarted, and a bad config is not") {
#ifdef GEARPULSE_SANITIZED
  GEARPULSE_SKIP_TEST("the unit's sandbox is checked on the release binary, not under a sanitizer's runtime");
#endif
  const auto r =
      run_shell("sh '" GEARPULSE_SOURCE_DIR "/tests/daemon/systemd_namespace.sh' '" + kUnitPath + "' '" +
                kDaemon + "' '" GEARPULSE_SOURCE_DIR "/systemd/gearpulse.sysusers.conf' 2>&1");
  INFO(r.out);
  if (const auto at = r.out.find("GEARPULSE_SKIP: "); at != std::string::npos)
    GEARPULSE_SKIP_TEST(r.out.substr(at + 16));
  CHECK(r.status == 0);
  for (const char* check : {"started", "kill-9", "watchdog", "reload", "stop", "bad-config"})
    CHECK(r.out.find(std::string("check ") + check + ": ok") != std::string::npos);
}
