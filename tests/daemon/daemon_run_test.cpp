// Runs the built gearpulsed as a process: no gpsd, no sound card, output "none". Start, the control
// socket, the output, stop, the config, systemd's notifications and watchdog, reloads. Its state
// directory is in daemon_state_test.cpp, gearpulsectl against it in gearpulsectl_test.cpp.
#include <catch2/catch.hpp>

#include <fcntl.h>
#include <signal.h>
#include <sys/ptrace.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <limits>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/training_store.hpp"
#include "daemon/watchdog.hpp"
#include "drivers/unique_fd.hpp"
#include "tests/daemon/daemon_process.hpp"
#include "tests/drivers/alsa_fifo.hpp"
#include "tests/test_util.hpp"

using gearpulse::test::ask;
using gearpulse::test::config_for;
using gearpulse::test::kDaemon;
using gearpulse::test::log_says;
using gearpulse::test::Process;
using gearpulse::test::pty_config_for;
using gearpulse::test::read_text;
using gearpulse::test::TempDir;
using gearpulse::test::wait_for_status;
using gearpulse::test::with;
using gearpulse::test::write_text;
using nlohmann::json;

TEST_CASE("daemon: runs with output none and no gpsd or ALSA and answers status") {
  TempDir dir;
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json status = wait_for_status(dir, daemon);
  INFO(read_text(dir / "log.txt"));
  REQUIRE(status.is_object());
  CHECK(status["v"] == 1);
  CHECK(status["ok"] == true);
  for (const char* key :
       {"speed", "source", "gear", "pulses", "gears", "uptime", "gps", "audio", "tracker", "model"})
    CHECK(status.contains(key));
  CHECK(status["gears"].is_array());
  CHECK(status["gears"].empty());
  CHECK(status["model"]["state"] == "learning");
  CHECK(status["gps"]["state"] != "fix");
  CHECK(status["pulses"] == 0);
  // A new install: no gear known, the learning schedule waiting for a first gear.
  CHECK(status["model"]["known_gears"] == json::array());
  CHECK(status["model"]["learning"]["young"] == true);
  CHECK(status["model"]["learning"]["moving_time"] == 0.0);
  CHECK(status["model"]["learning"]["cluster_pairs"] == 0);
  CHECK(status["model"]["learning"]["first_fit_pairs"] == 40);

  // reset-model needs an explicit confirmation.
  const json refused = ask(dir, R"({"v":1,"cmd":"reset-model"})");
  CHECK(refused["ok"] == false);
  CHECK(refused["error"].get<std::string>().find("confirm") != std::string::npos);
  CHECK(ask(dir, R"({"v":1,"cmd":"reset-model","confirm":false})")["ok"] == false);
  // A keep_samples that is not a boolean is said so, before anything is forgotten.
  const json odd = ask(dir, R"({"v":1,"cmd":"reset-model","confirm":true,"keep_samples":"yes"})");
  CHECK(odd["ok"] == false);
  CHECK(odd["error"].get<std::string>().find("keep_samples") != std::string::npos);
  CHECK(ask(dir, R"({"v":1,"cmd":"reset-model","confirm":true})")["ok"] == true);
  CHECK(ask(dir, R"({"v":1,"cmd":"nonsense"})")["ok"] == false);
  // The command is named whole, escaped, even with a NUL inside (it ended the message there).
  CHECK(ask(dir, R"({"v":1,"cmd":"st\u0000atus\n'"})")["error"] ==
        R"(unknown command 'st\u0000atus\u000a\'' (status, gears, retrain, reset-model))");
  CHECK(ask(dir, R"({"v":1,"cmd":"gears"})")["model_state"] == "learning");
  CHECK(ask(dir, R"({"v":1,"cmd":"retrain"})")["ok"] == true);

  // Still up a moment later, with missing devices retried rather than fatal.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  CHECK(daemon.running());
  CHECK(wait_for_status(dir, daemon)["ok"] == true);
  // The tracker thread turns while the pipeline runs, here for its steps on GPS alone and its heartbeat:
  // tracker.turns grows (several times a second; the 10 s only bound a failing test).
  REQUIRE(status["tracker"]["turns"].is_number_unsigned());
  const auto turns_then = status["tracker"]["turns"].get<std::uint64_t>();
  CHECK(gearpulse::test::wait_for(
      [&] {
        const json now = wait_for_status(dir, daemon)["tracker"]["turns"];
        return now.is_number_unsigned() && now.get<std::uint64_t>() > turns_then;
      },
      std::chrono::seconds(10)));

  daemon.signal(SIGHUP);
  CHECK(wait_for_status(dir, daemon)["ok"] == true);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
  // The absent gpsd is said at once (later failures at most once a minute).
  CHECK(read_text(dir / "log.txt").find("reconnecting with backoff") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(dir / "ctl.sock"));
  CHECK(std::filesystem::exists(dir / "state/training.bin"));
}

// systemd starts a service at 1024 descriptors whatever the hard limit; at the soft limit the control
// server can accept no one, the daemon's own user neither.
TEST_CASE("daemon: the descriptor limit is raised to the hard one, and one too low is said") {
  TempDir dir;
  write_text(dir / "gearpulse.toml", with(config_for(dir), "[control]\n", "[control]\nmax_clients = 1024\n"));
  for (const char* limit : {"--nofile=256:4096", "--nofile=256:512"}) {
    INFO(limit);
    Process daemon({"/usr/bin/prlimit", limit, kDaemon, "--config", (dir / "gearpulse.toml").string()},
                   dir / "log.txt");
    REQUIRE(wait_for_status(dir, daemon).is_object());
    const std::string limits = read_text("/proc/" + std::to_string(daemon.pid()) + "/limits");
    const std::size_t at = limits.find("Max open files");
    REQUIRE(at != std::string::npos);
    std::istringstream row(limits.substr(at + std::string_view("Max open files").size()));
    long soft = 0, hard = 0;
    row >> soft >> hard;
    const bool high = std::string_view(limit) == "--nofile=256:4096";
    CHECK(soft == hard);
    CHECK(hard == (high ? 4096 : 512));
    daemon.signal(SIGTERM);
    CHECK(daemon.wait() == 0);
    const bool said =
        read_text(dir / "log.txt").find("control.max_clients (1024) connections need") != std::string::npos;
    CHECK(said == !high);
  }
}

TEST_CASE("daemon: reset-model says so when the training pairs cannot be cleared from disk") {
  TempDir dir;
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  REQUIRE(wait_for_status(dir, daemon).is_object());
  // A store file that can be neither replaced nor removed: a directory with something in it.
  std::filesystem::create_directories(dir / "state/training.bin/keep");
  const json reply = ask(dir, R"({"v":1,"cmd":"reset-model","confirm":true})");
  INFO(reply.dump());
  CHECK(reply["ok"] == false);
  CHECK(reply["error"].get<std::string>().find("cannot be cleared") != std::string::npos);
  std::filesystem::remove_all(dir / "state/training.bin");
  CHECK(ask(dir, R"({"v":1,"cmd":"reset-model","confirm":true})")["ok"] == true);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: a PTY output in a directory that does not exist yet is made there") {
  TempDir dir;
  const std::filesystem::path link = dir / "run" / "sub" / "pulse";
  write_text(dir / "gearpulse.toml", pty_config_for(dir, link));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json status = wait_for_status(dir, daemon);
  INFO(read_text(dir / "log.txt"));
  REQUIRE(status.is_object());
  CHECK(status["output"]["error"] == "");
  CHECK(std::filesystem::is_symlink(link));
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: an output that will not open is retried until it does, without a restart") {
  TempDir dir;
  const std::filesystem::path link = dir / "pulse";
  write_text(link, "a file where the link should go\n");  // the PTY output refuses to replace it
  write_text(dir / "gearpulse.toml", pty_config_for(dir, link));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json failing = wait_for_status(dir, daemon);
  INFO(read_text(dir / "log.txt"));
  REQUIRE(failing.is_object());
  CHECK(failing["output"]["state"] == "error");
  CHECK(failing["output"]["error"].get<std::string>().find("not a symlink") != std::string::npos);
  std::filesystem::remove(link);
  // Waited for in status, not by the link: opening the PTY makes the link, and the daemon takes the
  // output for open only once it holds the device (a status asked in between still says "error").
  json status;
  CHECK(gearpulse::test::wait_for(
      [&] {
        status = wait_for_status(dir, daemon);
        return status["output"]["state"] == "no-reader";
      },
      std::chrono::seconds(15)));
  CHECK(std::filesystem::is_symlink(link));
  // Open, but no process has the device open: said in status and once in the log.
  CHECK(status["output"]["unheard"] == 0);  // no GPS: no pulses yet
  CHECK(status["output"]["error"] == "");
  // The log is written by its own thread: waited for.
  CHECK(log_says(dir, "opened on a retry", std::chrono::seconds(15)));
  CHECK(log_says(dir, "no process has " + link.string() + " open", std::chrono::seconds(15)));
  {
    const gearpulse::UniqueFd reader(::open(link.c_str(), O_RDONLY | O_NOCTTY | O_NONBLOCK));
    REQUIRE(reader);
    CHECK(log_says(dir, "a reader has " + link.string() + " open", std::chrono::seconds(15)));
    CHECK(wait_for_status(dir, daemon)["output"]["state"] == "ok");
  }
  CHECK(gearpulse::test::wait_for(
      [&] { return wait_for_status(dir, daemon)["output"]["state"] == "no-reader"; },
      std::chrono::seconds(15)));
  const std::string log = read_text(dir / "log.txt");
  std::size_t said = 0;
  for (std::size_t at = 0; (at = log.find("no process has", at)) != std::string::npos; ++at)
    ++said;
  CHECK(said == 1);  // the reader's return and second leave within a minute: not said again
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: SIGTERM saves what is learned before it waits for a capture stuck in the device") {
  TempDir dir;
  // A capture whose read never returns: the file plugin reads a FIFO whose writer is there but silent.
  const std::filesystem::path fifo = gearpulse::test::make_paced_pcm(dir, "stuck");
  // Closed however the test ends, so a failed check cannot leave the daemon stuck.
  gearpulse::UniqueFd writer(::open(fifo.c_str(), O_RDWR | O_CLOEXEC));
  REQUIRE(writer);
  write_text(dir / "gearpulse.toml", with(config_for(dir), "gearpulse_test_no_such_pcm", "stuck"));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  // The capture is open (so its thread is in, or about to be in, its read).
  json status;
  for (int i = 0; i < 300 && !(status.is_object() && status["audio"]["state"] == "running"); ++i) {
    status = wait_for_status(dir, daemon);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  REQUIRE(status["audio"]["state"] == "running");
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  daemon.signal(SIGTERM);
  // The store is saved while the daemon still waits for the capture thread.
  const bool saved = log_says(dir, "(shutdown)", std::chrono::seconds(15));
  INFO(read_text(dir / "log.txt"));
  CHECK(saved);
  CHECK(std::filesystem::exists(dir / "state/training.bin"));
  CHECK(log_says(dir, "has not returned from the device", std::chrono::seconds(15)));
  CHECK(daemon.running());
  writer.reset();  // the read returns (end of file): the daemon can finish
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: a second gearpulsed on the same state directory exits before it touches it") {
  TempDir dir;
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process first({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "first.txt");
  REQUIRE(wait_for_status(dir, first).is_object());
  // As if the first were in the middle of a save: its temp file must survive the second's start.
  write_text(dir / "state/training.bin.tmp.AbC123", "half a save");
  // The second has a socket of its own, so only the state directory is shared.
  write_text(dir / "second.toml",
             with(config_for(dir), (dir / "ctl.sock").string(), (dir / "other.sock").string()));
  Process second({kDaemon, "--config", (dir / "second.toml").string()}, dir / "second.txt");
  const auto rc = second.wait();
  REQUIRE(rc.has_value());
  CHECK(*rc == 1);
  CHECK(read_text(dir / "second.txt").find("another gearpulsed keeps its state in") != std::string::npos);
  CHECK(read_text(dir / "state/training.bin.tmp.AbC123") == "half a save");
  CHECK(first.running());
  first.signal(SIGTERM);
  CHECK(first.wait() == 0);
}

TEST_CASE("daemon: a malformed config is refused with file and line before anything opens") {
  TempDir dir;
  write_text(dir / "bad.toml",
             "[audio]\nrate = 48000\n\n[output]\nkind = \"none\"\npulses_per_km = 0\n[control]\nsocket = \"" +
                 (dir / "ctl.sock").string() + "\"\n");
  Process daemon({kDaemon, "--config", (dir / "bad.toml").string()}, dir / "log.txt");
  const auto rc = daemon.wait();
  REQUIRE(rc.has_value());
  CHECK(*rc != 0);
  const std::string log = read_text(dir / "log.txt");
  CHECK(log.find((dir / "bad.toml").string() + ":6: output.pulses_per_km:") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(dir / "ctl.sock"));

  Process check({kDaemon, "--config", (dir / "bad.toml").string(), "--check-config"}, dir / "log2.txt");
  CHECK(check.wait() == 2);
  write_text(dir / "good.toml", config_for(dir));
  Process good({kDaemon, "--config", (dir / "good.toml").string(), "--check-config"}, dir / "log3.txt");
  CHECK(good.wait() == 0);
}

TEST_CASE("daemon: a config that never ends or never opens is refused with exit 2, naming it") {
  TempDir dir;
  const std::string fifo = (dir / "fifo.toml").string();
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  int n = 0;
  for (const std::string& path : {std::string("/dev/zero"), fifo}) {
    CAPTURE(path);
    const auto log = dir / ("log" + std::to_string(++n) + ".txt");
    Process check({kDaemon, "--config", path, "--check-config"}, log);
    CHECK(check.wait(10'000) == 2);
    CHECK(read_text(log).find("gearpulsed: " + path + ": cannot read config file: not a regular file") !=
          std::string::npos);
  }
}

TEST_CASE("daemon: a PTY link whose directory cannot be made says why") {
  TempDir dir;
  write_text(dir / "run", "a file where a directory should be\n");
  write_text(dir / "gearpulse.toml", pty_config_for(dir, dir / "run" / "pulse"));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json status = wait_for_status(dir, daemon);
  REQUIRE(status.is_object());
  CHECK(status["output"]["state"] == "error");
  const std::string error = status["output"]["error"].get<std::string>();
  CHECK(error.find("cannot create the directory") != std::string::npos);
  CHECK(error.find("Not a directory") != std::string::npos);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: tells systemd ready and stopping and feeds the watchdog") {
  TempDir dir;
  const std::string notify_path = (dir / "notify").string();
  const gearpulse::UniqueFd notify(::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  REQUIRE(notify);
  const int sock = notify.get();
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, notify_path.c_str(), sizeof addr.sun_path - 1);
  REQUIRE(::bind(sock, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0);
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt",
                 {.env = {"NOTIFY_SOCKET=" + notify_path, "WATCHDOG_USEC=600000"}});
  std::string all;
  const auto receive_until = [&](const std::string& what) {
    for (int i = 0; i < 200 && all.find(what) == std::string::npos; ++i) {
      pollfd pfd{sock, POLLIN, 0};
      if (::poll(&pfd, 1, 100) <= 0) continue;
      char buf[4096];
      const ssize_t n = ::recv(sock, buf, sizeof buf, 0);
      if (n > 0) all.append(buf, static_cast<std::size_t>(n)).append("\n");
    }
    return all.find(what) != std::string::npos;
  };
  CHECK(receive_until("READY=1"));
  CHECK(all.find("STATUS=") != std::string::npos);
  CHECK(receive_until("WATCHDOG=1"));
  daemon.signal(SIGTERM);
  CHECK(receive_until("STOPPING=1"));
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: a thread that stops turning withholds WATCHDOG=1 until it turns again") {
  // Every thread but the main one is stopped (ptrace, a thread at a time: the main thread runs on and
  // judges the others' heartbeats), as a thread stuck in a driver would be.
  if (::geteuid() != 0) {
    std::puts("GEARPULSE_SKIP: needs root to stop the daemon's threads with ptrace");
    return;
  }
  TempDir dir;
  const std::string notify_path = (dir / "notify").string();
  const gearpulse::UniqueFd notify(::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  REQUIRE(notify);
  const int sock = notify.get();
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, notify_path.c_str(), sizeof addr.sun_path - 1);
  REQUIRE(::bind(sock, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0);
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt",
                 {.env = {"NOTIFY_SOCKET=" + notify_path, "WATCHDOG_USEC=2000000"}});
  // The WATCHDOG=1 messages that arrive within `ms` (returned early once there are `enough`).
  const auto pings_within = [&](int ms, int enough = std::numeric_limits<int>::max()) {
    int pings = 0;
    const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
    while (pings < enough && std::chrono::steady_clock::now() < until) {
      pollfd pfd{sock, POLLIN, 0};
      if (::poll(&pfd, 1, 50) <= 0) continue;
      char buf[4096];
      const ssize_t n = ::recv(sock, buf, sizeof buf, 0);
      if (n > 0 && std::string_view(buf, static_cast<std::size_t>(n)).find("WATCHDOG=1") != std::string::npos)
        ++pings;
    }
    return pings;
  };
  REQUIRE(wait_for_status(dir, daemon).is_object());
  // A ping a tick (a third of WATCHDOG_USEC): two are waited for up to 10 s, room for a loaded machine.
  CHECK(pings_within(10'000, 2) >= 2);
  std::vector<pid_t> stopped;
  for (const auto& task :
       std::filesystem::directory_iterator("/proc/" + std::to_string(daemon.pid()) + "/task")) {
    const pid_t tid = std::stoi(task.path().filename().string());
    if (tid == daemon.pid()) continue;
    if (::ptrace(PTRACE_SEIZE, tid, nullptr, nullptr) != 0) continue;
    if (::ptrace(PTRACE_INTERRUPT, tid, nullptr, nullptr) == 0 && ::waitpid(tid, nullptr, __WALL) == tid)
      stopped.push_back(tid);
  }
  REQUIRE(stopped.size() >= 3);  // the tracker, GPS and pulse threads at least
  // Within the stall limit (5 s) and a tick (0.67 s) the pings stop, and stay stopped: longer than the
  // unit's WatchdogSec (10 s) systemd kills the daemon and, by Restart=on-failure, starts it again. The
  // 3 s after the stall limit leave a loaded machine 2.3 s past the tick to see the stall, and still end
  // before WatchdogSec.
  (void)pings_within(static_cast<int>(gearpulse::daemon::kStallNs / 1'000'000) + 3'000);
  CHECK(pings_within(3'000) == 0);
  CHECK(daemon.running());
  for (const pid_t tid : stopped)
    ::ptrace(PTRACE_DETACH, tid, nullptr, nullptr);
  CHECK(pings_within(10'000, 2) >= 2);
  CHECK(log_says(dir, "thread(s) not responding: ", std::chrono::seconds(15)));
  const std::string unit = read_text(GEARPULSE_SOURCE_DIR "/systemd/gearpulsed.service.in");
  CHECK(unit.find("\nWatchdogSec=") != std::string::npos);
  CHECK(unit.find("\nRestart=on-failure\n") != std::string::npos);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: a reload whose store limits drop stored pairs says how many") {
  TempDir dir;
  std::filesystem::create_directories(dir / "state");
  gearpulse::daemon::TrainingStore store(1e9, 1000);
  const double now = static_cast<double>(std::time(nullptr));
  for (int i = 0; i < 300; ++i)
    store.add({now - 600.0 + i, 10.0, 50.0});
  store.save(dir / "state/training.bin");
  const std::string base = config_for(dir);
  write_text(dir / "gearpulse.toml", base);
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  REQUIRE(wait_for_status(dir, daemon)["training_samples"] == 300);
  write_text(dir / "gearpulse.toml",
             with(base, "[model]\n", "[model]\nmax_samples = 100\nmin_new_samples = 100\n"));
  daemon.signal(SIGHUP);
  const bool said = log_says(dir, "drop 200 of its 300 pairs", std::chrono::seconds(15));
  INFO(read_text(dir / "log.txt"));
  CHECK(said);
  CHECK(wait_for_status(dir, daemon)["training_samples"] == 100);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: SIGHUP applies what it can and names what needs a restart") {
  TempDir dir;
  const std::string base = config_for(dir);
  write_text(dir / "gearpulse.toml", base);
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  REQUIRE(wait_for_status(dir, daemon).is_object());
  const auto wait_log = [&](const std::string& what) {
    return log_says(dir, what, std::chrono::seconds(15));
  };
  // A broken file on reload is refused; the daemon keeps its running configuration.
  write_text(dir / "gearpulse.toml", base + "[bogus]\n");
  daemon.signal(SIGHUP);
  CHECK(wait_log("keeping the running configuration"));
  const json refused = wait_for_status(dir, daemon);
  CHECK(refused["ok"] == true);
  CHECK(refused["config"]["reload_error"].get<std::string>().find("bogus") != std::string::npos);
  // A file that is not there: the reason is given.
  std::filesystem::rename(dir / "gearpulse.toml", dir / "moved.toml");
  daemon.signal(SIGHUP);
  CHECK(wait_log("cannot open config file: No such file or directory"));
  std::filesystem::rename(dir / "moved.toml", dir / "gearpulse.toml");

  std::string changed = base;
  changed.replace(changed.find("gearpulse_test_no_such_pcm"), 26, "gearpulse_test_other_pcm__");
  changed.replace(changed.find("[model]\n"), 8, "[model]\nmin_new_samples = 7\n");
  write_text(dir / "gearpulse.toml", changed);
  daemon.signal(SIGHUP);
  CHECK(wait_log("reload: audio.device changed; this takes effect only after a restart"));
  CHECK(wait_log("reload: applied"));
  const json applied = wait_for_status(dir, daemon);
  CHECK(applied["ok"] == true);
  CHECK(applied["config"]["reload_error"] == "");
  CHECK(applied["config"]["restart_pending"] == json::array({"audio.device"}));
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}
