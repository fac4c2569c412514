#pragma once
// The built gearpulsed run as a process: no gpsd, no sound card, output "none" unless a test says
// otherwise; its configs, its status over the control socket, and a state directory to start it on.
#include <catch2/catch.hpp>

#include <signal.h>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <thread>

#include <nlohmann/json.hpp>

#include "daemon/training_store.hpp"
#include "tests/test_util.hpp"
#include "tools/sim/vehicle_sim.hpp"

namespace gearpulse::test {

inline const std::string kDaemon = GEARPULSE_BINARY_DIR "/daemon/gearpulsed";

inline std::string config_for(const TempDir& dir, const std::string& extra_output = "") {
  return "[audio]\ndevice = \"gearpulse_test_no_such_pcm\"\n"
         "[gps]\nhost = \"127.0.0.1\"\nport = " +
         std::to_string(free_port()) +
         "\n"
         "[output]\nkind = \"none\"\n" +
         extra_output + "[model]\nstate_dir = \"" + (dir / "state").string() +
         "\"\n"
         "[control]\nsocket = \"" +
         (dir / "ctl.sock").string() + "\"\n[log]\nlevel = \"debug\"\n";
}

// `text` with its first `from` replaced by `to` (a config_for() with one setting changed).
inline std::string with(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  REQUIRE(at != std::string::npos);
  return text.replace(at, from.size(), to);
}

// config_for() with its output on a PTY whose link is `link`.
inline std::string pty_config_for(const TempDir& dir, const std::filesystem::path& link) {
  return with(config_for(dir), "kind = \"none\"\n", "kind = \"pty\"\npath = \"" + link.string() + "\"\n");
}

// Status once the daemon answers, or null after the timeout.
inline nlohmann::json wait_for_status(const TempDir& dir, Process& daemon, int timeout_ms = 15'000) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline && daemon.running()) {
    LineClient c((dir / "ctl.sock").string());
    if (c.connected() && c.send_all("{\"v\":1,\"cmd\":\"status\"}\n"))
      if (const auto line = c.read_line()) return nlohmann::json::parse(*line);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return nullptr;
}

// Starts the daemon on dir's gearpulse.toml, waits for its first status, stops it with SIGTERM (it must
// exit 0) and returns that status (null if it never answered).
inline nlohmann::json status_of_one_run(const TempDir& dir) {
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  nlohmann::json status = wait_for_status(dir, daemon);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
  return status;
}

inline nlohmann::json ask(const TempDir& dir, const std::string& request) {
  LineClient c((dir / "ctl.sock").string());
  REQUIRE(c.connected());
  REQUIRE(c.send_all(request + "\n"));
  const auto line = c.read_line();
  REQUIRE(line.has_value());
  return nlohmann::json::parse(*line);
}

inline constexpr const char* kModel = R"({"version":1,"gears":[{"theta":0.043,"weight":0.2,"stderr":0.0002},
{"theta":0.072,"weight":0.3,"stderr":0.0003},{"theta":0.106,"weight":0.5,"stderr":0.0004}],
"sigma_speed":0.3,"sigma_freq":0.6,"samples":1234,"log_likelihood":-10.5})";

// Saves in `dir`/state a training store of a 40-minute bmw-520i drive (seed `seed`) that ended at
// `end_wall_s`, and a config that retrains at start on 1000 new pairs; returns the store's size.
inline std::size_t store_a_drive(const TempDir& dir, std::uint64_t seed, double end_wall_s) {
  std::filesystem::create_directories(dir / "state");
  const auto obs =
      sim::simulate_observations(sim::vehicle_preset("bmw-520i"), sim::DrivingStyle::kMixed, 2400.0, 1, seed);
  daemon::TrainingStore store(1e9, 1'000'000);
  for (const auto& s : sim::to_samples(obs))
    store.add({end_wall_s - 2400.0 + s.t, s.speed, s.freq});
  store.save(dir / "state/training.bin");
  // config_for already has a [model] table: the retrain keys go into it.
  std::string text = config_for(dir);
  text.replace(text.find("[model]\n"), 8, "[model]\nmin_new_samples = 1000\nretrain_interval = 3600\n");
  write_text(dir / "gearpulse.toml", text);
  return store.size();
}

// Status once `done` holds for it (or the daemon answers no more, or 100 s have passed). The bound is a
// failing test's only: what is waited for is a fit, which runs at idle priority and on a loaded machine (a
// sanitized build beside other tests) gets a core only when nothing else wants it; a minute was too short
// there. Two such waits, each with its last status read (up to 15 s), and a test's other waits still end
// within ctest's 300 s for a test, so a failure prints its log rather than a timeout.
template <class Done>
nlohmann::json status_once(const TempDir& dir, Process& daemon, Done done) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(100);
  nlohmann::json status;
  do {
    status = wait_for_status(dir, daemon);
    if (!status.is_object() || done(status)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  } while (std::chrono::steady_clock::now() < deadline);
  return status;
}

// Waits up to `timeout` for the daemon's log (dir/log.txt) to say `text`. The log is written by a thread
// of its own: a line said before status answered may reach the file after the answer, so a line of a
// running daemon is always waited for, never read at once.
inline bool log_says(const TempDir& dir, std::string_view text, std::chrono::milliseconds timeout) {
  return wait_for([&] { return read_text(dir / "log.txt").find(text) != std::string::npos; }, timeout);
}

}  // namespace gearpulse::test
