// End to end: gearpulsed on a simulated drive through the real components (ALSA file plugin fed by a
// real-time FIFO, gpsd via gpsfake, PTY output), driven by scripts/lib/harness.sh exactly as the demo.
#include <signal.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include "tests/test_util.hpp"

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

const std::string kHarness = GEARPULSE_SOURCE_DIR "/scripts/lib/harness.sh";
const std::string kBuild = GEARPULSE_BINARY_DIR;
constexpr double kPulsesPerKm = 2485.0;

using Result = gearpulse::test::ShellResult;

// Runs a shell command, stdout captured (stderr passes through to the test log).
Result run(const std::string& command) {
  return gearpulse::test::run_shell(command);
}

std::string quote(const std::string& s) {
  return "'" + s + "'";
}

bool have_gpsfake() {
  return run("PATH=/usr/bin:$PATH command -v gpsfake >/dev/null 2>&1").status == 0;
}

std::string slurp(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A unique work directory, the harness stopped and the directory removed however the test ends.
struct Work {
  fs::path dir;
  Work() {
    std::string templ = (fs::temp_directory_path() / "gearpulse-e2e.XXXXXX").string();
    if (::mkdtemp(templ.data()) != nullptr) dir = templ;
  }
  ~Work() {
    if (dir.empty()) return;
    run("bash " + quote(kHarness) + " stop " + quote(dir.string()) + " >/dev/null 2>&1");
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  Work(const Work&) = delete;
  Work& operator=(const Work&) = delete;

  Result harness(const std::string& args) const {
    return run("bash " + quote(kHarness) + " " + args + " 2>&1");
  }
  // Prepares a drive (`simulate_args` for gearpulse-devtools simulate, `env` the harness's variables) and
  // starts gpsfake, the feeder and the daemon on it.
  void start_drive(const std::string& env, const std::string& simulate_args) const {
    const std::string wd = quote(dir.string());
    const Result prepared = run(env + " bash " + quote(kHarness) + " prepare " + wd + " " + quote(kBuild) +
                                " " + simulate_args + " 2>&1");
    INFO(prepared.out);
    REQUIRE(prepared.status == 0);
    const Result started = harness("start " + wd);
    INFO(started.out);
    REQUIRE(started.status == 0);
  }
  json status() const {
    const Result r = run(quote(kBuild + "/tools/gearpulsectl") + " --socket " +
                         quote((dir / "control.sock").string()) + " status --json 2>/dev/null");
    if (r.status != 0) return json();
    return json::parse(r.out, nullptr, false);
  }
  pid_t pid(const std::string& name) const {
    const std::string s = slurp(dir / "pids" / name);
    return s.empty() ? -1 : static_cast<pid_t>(std::stol(s));
  }
};

// The true distance (m) driven between drive times a and b, trapezoidal over truth.csv (the simulator's
// truth, not the daemon's).
double truth_distance_between(const fs::path& truth_csv, double a, double b) {
  std::ifstream in(truth_csv);
  std::string line;
  std::getline(in, line);  // header t,speed,freq,gear
  double d = 0.0, t0 = 0.0, v0 = 0.0;
  bool first = true;
  while (std::getline(in, line)) {
    double t = 0.0, v = 0.0;
    if (std::sscanf(line.c_str(), "%lf,%lf", &t, &v) != 2) continue;
    if (!first && t > a && t0 < b) d += 0.5 * (v + v0) * (std::min(t, b) - std::max(t0, a));
    first = false;
    t0 = t;
    v0 = v;
  }
  return d;
}

// The true distance of the whole drive.
double truth_distance_m(const fs::path& truth_csv) {
  return truth_distance_between(truth_csv, -INFINITY, INFINITY);
}

// The true speed (m/s) at drive time t, from truth.csv (the row at or before t).
double truth_speed_at(const fs::path& truth_csv, double t) {
  std::ifstream in(truth_csv);
  std::string line;
  std::getline(in, line);  // header t,speed,freq,gear
  double speed = 0.0;
  while (std::getline(in, line)) {
    double row_t = 0.0, v = 0.0;
    if (std::sscanf(line.c_str(), "%lf,%lf", &row_t, &v) != 2) continue;
    if (row_t > t) break;
    speed = v;
  }
  return speed;
}

std::vector<double> thetas(const json& status) {
  std::vector<double> out;
  if (!status.is_object() || !status.contains("gears")) return out;
  for (const json& g : status["gears"])
    out.push_back(g.value("theta", NAN));
  return out;
}

// GPS fixes of an NMEA log as gpsd would report them: (drive time, speed m/s) of every valid RMC, the
// drive's t = 0 stamped 12:00:00 UTC (gearpulse simulate).
std::vector<std::pair<double, double>> nmea_fixes(const fs::path& nmea) {
  std::vector<std::pair<double, double>> fixes;
  std::ifstream in(nmea);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("$GPRMC,", 0) != 0) continue;
    std::vector<std::string> f;
    std::stringstream ss(line);
    for (std::string cell; std::getline(ss, cell, ',');)
      f.push_back(cell);
    if (f.size() < 8 || f[2] != "A" || f[1].size() < 6 || f[7].empty()) continue;
    const double hms = std::stod(f[1]);
    const double tod = std::floor(hms / 10000.0) * 3600.0 +
                       std::floor(std::fmod(hms, 10000.0) / 100.0) * 60.0 + std::fmod(hms, 100.0);
    constexpr double kKnot = 1852.0 / 3600.0;
    fixes.emplace_back(tod - 12.0 * 3600.0, std::stod(f[7]) * kKnot);
  }
  return fixes;
}

// What `gearpulse replay` makes of the daemon's inputs: the engine frequency `gearpulse track` reads from
// the drive's audio with the daemon's tracker settings, every fix held for the daemon's GPS timeout as
// the daemon holds it. Returns the distance (m) the replay synthesized from the first row GPS was lost to
// the first row it was back after `after` (drive time), and those rows' times; a distance of -1 if there
// is none.
struct Outage {
  double distance = -1.0, from = 0.0, to = 0.0;
};
Outage replay_outage(const fs::path& work, double after, double gps_timeout) {
  const fs::path drive = work / "drive";
  const Result track =
      run(quote(kBuild + "/tools/gearpulse") + " track " + quote((drive / "drive.wav").string()));
  if (track.status != 0) return {};
  const auto fixes = nmea_fixes(drive / "drive.nmea");
  const fs::path merged = work / "replay-input.csv";
  {
    std::ofstream out(merged);
    out << "t,speed,freq\n";
    std::stringstream rows(track.out);
    std::string line;
    std::getline(rows, line);  // t,freq,snr_db
    std::size_t next = 0;
    double fix_t = -1e9, fix_v = 0.0;
    while (std::getline(rows, line)) {
      std::stringstream cells(line);
      std::string t_cell, f_cell;
      std::getline(cells, t_cell, ',');
      std::getline(cells, f_cell, ',');
      const double t = std::stod(t_cell);
      while (next < fixes.size() && fixes[next].first <= t + 1e-9)
        fix_t = fixes[next].first, fix_v = fixes[next].second, ++next;
      out << t_cell << ',';
      if (t - fix_t <= gps_timeout) out << fix_v;
      out << ',' << f_cell << '\n';
    }
  }
  // --band-low: the daemon's tracker.band_low (its default: the harness' config leaves it), so that replay
  // knows what the readings can show as the daemon does.
  const Result replay = run(quote(kBuild + "/tools/gearpulse") + " replay --band-low 50 --model " +
                            quote((work / "state" / "model.json").string()) + " " + quote(merged.string()));
  if (replay.status != 0) return {};
  std::stringstream rows(replay.out);
  std::string line;
  std::getline(rows, line);  // t,speed,gear,source
  Outage outage{0.0};
  double last_t = 0.0, last_v = 0.0;
  bool out_now = false, seen = false;
  while (std::getline(rows, line)) {
    double t = 0.0, v = 0.0;
    int gear = 0;
    char source[16] = {};
    if (std::sscanf(line.c_str(), "%lf,%lf,%d,%15s", &t, &v, &gear, source) != 4) continue;
    if (out_now) outage.distance += last_v * (t - last_t);
    const bool gps = std::string(source) == "gps";
    if (t > after && !gps && !seen) out_now = seen = true, outage.from = t;
    if (out_now && gps) {
      outage.to = t;
      return outage;
    }
    last_t = t;
    last_v = v;
  }
  return {};
}

// The pulses a drive should give (its true distance at kPulsesPerKm) and those the PTY's reader counted,
// printed under `label`.
struct PulseCount {
  double distance = 0.0, expected = 0.0, counted = 0.0;
};
PulseCount count_pulses(const Work& work, const char* label) {
  PulseCount c;
  c.distance = truth_distance_m(work.dir / "drive" / "truth.csv");
  c.expected = c.distance / 1000.0 * kPulsesPerKm;
  c.counted = static_cast<double>(fs::file_size(work.dir / "pulses.bin"));
  std::printf("%s: %.0f m, %.0f pulses expected, %.0f counted (%+.2f %%)\n", label, c.distance, c.expected,
              c.counted, c.expected > 0.0 ? 100.0 * (c.counted / c.expected - 1.0) : 0.0);
  return c;
}

// The reader drains the PTY: waits until pulses.bin holds every pulse the daemon wrote to it and did not take
// back (`output.unheard` were emitted while no reader held the PTY, `output.dropped` were never written or
// flushed as stale), or 10 s.
void wait_for_pty_drain(const Work& work) {
  const auto drained = [&] {
    const json s = work.status();
    if (!s.is_object()) return false;
    const json output = s.value("output", json::object());
    const double written =
        s.value("pulses", 0.0) - output.value("unheard", 0.0) - output.value("dropped", 0.0);
    return static_cast<double>(fs::file_size(work.dir / "pulses.bin")) >= written;
  };
  for (int i = 0; i < 100 && !drained(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
}

double seconds_since(const fs::path& started_file) {
  const double started = std::stod(slurp(started_file));
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count() - started;
}

}  // namespace

TEST_CASE("e2e: pulses match the drive distance across a GPS outage and the model survives kill -9",
          "[e2e][daemon]") {
  if (!have_gpsfake())
    GEARPULSE_SKIP_TEST("gpsfake is not installed (apt-get install gpsd gpsd-clients python3-gps)");
  Work work;
  REQUIRE(!work.dir.empty());
  const std::string wd = quote(work.dir.string());
  // 16 kHz keeps the daemon's CPU low under the sanitizers; the drive starts and ends at rest.
  const double outage_start = 45.0, outage_length = 60.0;
  work.start_drive("GEARPULSE_RATE=16000 GEARPULSE_PERIOD=512", "--seed 7 --duration 140 --outage 45:60");

  // Poll the status while the drive plays (the feeder exits at the end of the audio).
  std::vector<std::pair<double, std::string>> outage_polls;  // (drive time, source)
  int gps_after_outage = 0;
  // The pulse count where the daemon lost GPS and where it had it back, and the time between the polls
  // that bracket each edge.
  double pulses_lost = -1.0, pulses_back = -1.0, edge_gap = 0.0, last_poll = 0.0;
  double lost_at = 0.0, back_at = 0.0;
  std::uint64_t late_hops = 0;  // hops the daemon stepped after a backlog (its status's tracker.late_hops)
  const pid_t feeder = work.pid("feeder");
  REQUIRE(feeder > 0);
  while (::kill(feeder, 0) == 0) {
    const json s = work.status();
    const double t = seconds_since(work.dir / "drive.t0");
    if (s.is_object()) {
      const std::string source = s.value("source", "?");
      const double pulses = s.value("pulses", 0.0);
      if (t > outage_start - 5.0 && pulses_lost < 0.0 && source != "gps")
        pulses_lost = pulses, lost_at = t, edge_gap = std::max(edge_gap, t - last_poll);
      if (pulses_lost >= 0.0 && pulses_back < 0.0 && source == "gps")
        pulses_back = pulses, back_at = t, edge_gap = std::max(edge_gap, t - last_poll);
      last_poll = t;
      if (s.contains("tracker")) late_hops = s["tracker"].value("late_hops", late_hops);
      // Leave the GPS timeout and a second of slack at both edges of the outage.
      if (t > outage_start + 4.0 && t < outage_start + outage_length - 2.0)
        outage_polls.emplace_back(t, source);
      if (t > outage_start + outage_length + 8.0 && source == "gps") ++gps_after_outage;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  // The capture, open before the audio starts, waits less than its stall limit (2 s) for the first period
  // (scripts/lib/harness.sh), and the feeder keeps it fed to the drive's end: the daemon never says the
  // audio stalled. Its log is read as the feeder ends, before the end could look like a stall.
  const std::string drive_log = slurp(work.dir / "gearpulsed.log");
  wait_for_pty_drain(work);

  const auto [distance, expected, counted] = count_pulses(work, "e2e drive");
  INFO("distance " << distance << " m, pulses expected " << expected << ", counted " << counted);
  INFO("daemon log:\n" << slurp(work.dir / "gearpulsed.log").substr(0, 4000));
  REQUIRE(distance > 500.0);
  CHECK(std::abs(counted - expected) <= 0.03 * expected);

  // Live and replay run the same synthesis on the same inputs: the outage distance the daemon's pulses
  // carry and the one `gearpulse replay` synthesizes from the drive's audio and fixes err alike, each
  // against the distance the car drove in its own outage (gpsfake's clock runs apart from the audio's by a
  // second or two, so the daemon's outage starts and ends elsewhere in the drive than the log's). Within
  // 1 %, beside what the car covers between two polls at the daemon's edges and the tracker's lag.
  constexpr double kGpsTimeout = 1.5;  // s, the default gps.timeout the harness keeps
  const Outage replayed = replay_outage(work.dir, outage_start - 5.0, kGpsTimeout);
  const fs::path truth = work.dir / "drive" / "truth.csv";
  const double live = (pulses_back - pulses_lost) / kPulsesPerKm * 1000.0;
  const double live_truth = truth_distance_between(truth, lost_at, back_at);
  const double replay_truth = truth_distance_between(truth, replayed.from, replayed.to);
  constexpr double kLag = 0.3;  // s: the daemon's clock against the audio's, a tracker hop or two
  const double edges = (edge_gap + kLag) * (truth_speed_at(truth, lost_at) + truth_speed_at(truth, back_at));
  const double live_error = live / live_truth - 1.0, replay_error = replayed.distance / replay_truth - 1.0;
  std::printf(
      "e2e outage: daemon %.1f m over %.1f-%.1f s (driven %.1f m, %+.2f %%), replay %.1f m over %.1f-%.1f s "
      "(driven %.1f m, %+.2f %%); %llu hops stepped late\n",
      live, lost_at, back_at, live_truth, 100.0 * live_error, replayed.distance, replayed.from, replayed.to,
      replay_truth, 100.0 * replay_error, static_cast<unsigned long long>(late_hops));
  REQUIRE(pulses_lost >= 0.0);
  REQUIRE(pulses_back > pulses_lost);
  REQUIRE(replayed.distance > 100.0);
  REQUIRE(live_truth > 100.0);
  CHECK(std::abs(live_error - replay_error) <= 0.01 + edges / live_truth);

  // Inside the outage the speed comes from the engine while the car moves (declutched moments and a stop
  // at a light read as coast), never from GPS.
  std::map<std::string, int> outage_sources, moving_sources;
  int moving = 0;
  for (const auto& [t, source] : outage_polls) {
    ++outage_sources[source];
    constexpr double kMovingSpeed = 2.0;  // m/s
    if (truth_speed_at(work.dir / "drive" / "truth.csv", t) > kMovingSpeed)
      ++moving, ++moving_sources[source];
  }
  INFO("sources polled inside the outage: " << json(outage_sources).dump() << ", while moving "
                                            << json(moving_sources).dump());
  REQUIRE(outage_polls.size() >= 20);
  REQUIRE(moving >= 10);
  CHECK(outage_sources["gps"] == 0);
  CHECK(moving_sources["engine"] >= 0.8 * moving);
  CHECK(gps_after_outage > 0);
  // At info level the log says when GPS was lost and back, not every declutch inside the outage.
  const std::string log = slurp(work.dir / "gearpulsed.log");
  CHECK(log.find("gps: connected to gpsd at 127.0.0.1:") != std::string::npos);
  CHECK(log.find("speed source gps -> ") != std::string::npos);
  CHECK(log.find(" -> gps at ") != std::string::npos);
  CHECK(log.find("speed source engine -> coast") == std::string::npos);
  CHECK(log.find("speed source coast -> engine") == std::string::npos);
  INFO("daemon log while the drive played:\n" << drive_log.substr(0, 4000));
  CHECK(drive_log.find("audio: no samples from") == std::string::npos);

  // Power cut: the model on disk must be the one the daemon had, loaded again at restart.
  const json before = work.status();
  REQUIRE(before.is_object());
  const std::vector<double> thetas_before = thetas(before);
  REQUIRE(!thetas_before.empty());
  // Live learning: fixes paired with the tracked engine frequency reached the training store (1 Hz GPS
  // over minutes of driving with a fix).
  CHECK(before.value("training_samples", 0) >= 30);
  REQUIRE(work.harness("kill-daemon " + wd).status == 0);
  // Compared on disk, not in the restarted daemon's status: a young model's schedule may refit it at start
  // on the journaled pairs, which lack the last seconds before the kill.
  const fs::path model_file = work.dir / "state" / "model.json";
  const json on_disk = json::parse(slurp(model_file), nullptr, false);
  const std::vector<double> thetas_on_disk = thetas(on_disk);
  REQUIRE(thetas_on_disk.size() == thetas_before.size());
  for (std::size_t i = 0; i < thetas_before.size(); ++i) {
    CHECK(thetas_on_disk[i] == Approx(thetas_before[i]).epsilon(1e-9));
  }
  const std::string loaded_line =
      "model: loaded " + model_file.string() + " (" + std::to_string(thetas_before.size()) + " gears";
  const auto loaded_count = [&] {
    const std::string text = slurp(work.dir / "gearpulsed.log");
    std::size_t n = 0;
    for (auto at = text.find(loaded_line); at != std::string::npos; at = text.find(loaded_line, at + 1))
      ++n;
    return n;
  };
  const std::size_t loaded_before = loaded_count();
  const Result restarted = work.harness("restart " + wd);
  INFO(restarted.out);
  REQUIRE(restarted.status == 0);
  const json after = work.status();
  REQUIRE(after.is_object());
  CHECK(after.value("model_state", "") == "trained");
  // The log has its own thread: its line may follow the first status reply.
  for (int i = 0; i < 100 && loaded_count() <= loaded_before; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  INFO("looked for '" << loaded_line << "' in the restarted daemon's log");
  CHECK(loaded_count() == loaded_before + 1);
  // The pairs were never saved (the store is saved every 5 minutes and at a stop); the journal kept all
  // but those of the last seconds before the kill.
  constexpr int kUnjournaled = 12;  // 10 s between journal appends at 1 Hz, and slack
  INFO("training pairs before the kill " << before.value("training_samples", 0) << ", after the restart "
                                         << after.value("training_samples", 0));
  CHECK(after.value("training_samples", 0) >= before.value("training_samples", 0) - kUnjournaled);
  CHECK(after.value("training_samples", 0) <= before.value("training_samples", 0));  // none twice
}

// A 10 Hz receiver (u-blox M8/M9, a phone through gpsd): the harness plays the log at 10 fixes a second in
// real time (scripts/lib/gps_player.py). The pulses and the outage go as at 1 Hz, the log says nothing per
// fix, and the store takes one training pair a second (PairSpacing), not ten.
TEST_CASE("e2e: 10 Hz GPS: pulses match across an outage, one training pair a second", "[e2e][daemon]") {
  if (!have_gpsfake())
    GEARPULSE_SKIP_TEST("gpsfake is not installed (apt-get install gpsd gpsd-clients python3-gps)");
  Work work;
  REQUIRE(!work.dir.empty());
  const double outage_start = 35.0, outage_length = 30.0;
  work.start_drive("GEARPULSE_GPS_HZ=10 GEARPULSE_RATE=16000 GEARPULSE_PERIOD=512",
                   "--seed 7 --duration 90 --outage 35:30");
  const std::string env = slurp(work.dir / "drive" / "drive.env");
  REQUIRE(env.find("gps_hz=10") != std::string::npos);

  std::map<std::string, int> outage_sources;
  int gps_after_outage = 0;
  const pid_t feeder = work.pid("feeder");
  REQUIRE(feeder > 0);
  while (::kill(feeder, 0) == 0) {
    const json s = work.status();
    const double t = seconds_since(work.dir / "drive.t0");
    if (s.is_object()) {
      const std::string source = s.value("source", "?");
      if (t > outage_start + 4.0 && t < outage_start + outage_length - 2.0) ++outage_sources[source];
      if (t > outage_start + outage_length + 8.0 && source == "gps") ++gps_after_outage;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  wait_for_pty_drain(work);

  const auto [distance, expected, counted] = count_pulses(work, "e2e 10 Hz drive");
  const std::string log = slurp(work.dir / "gearpulsed.log");
  INFO("daemon log:\n" << log.substr(0, 4000));
  REQUIRE(distance > 500.0);
  CHECK(std::abs(counted - expected) <= 0.03 * expected);
  INFO("sources polled inside the outage: " << json(outage_sources).dump());
  CHECK(outage_sources["gps"] == 0);
  CHECK(outage_sources["engine"] >= 10);
  CHECK(gps_after_outage > 0);
  CHECK(log.find("speed source gps -> ") != std::string::npos);
  CHECK(log.find(" -> gps at ") != std::string::npos);
  // Nothing said per fix: 10 fixes a second over the drive would be hundreds of lines.
  CHECK(std::count(log.begin(), log.end(), '\n') < 40);

  // One pair a second of the receiver's clock: at most the seconds the log has a fix in (its lead at rest,
  // the drive less the outage), where ten a second would be ten times that.
  const json s = work.status();
  REQUIRE(s.is_object());
  const double duration = std::stod(env.substr(env.find("duration_s=") + 11));
  const double lead = std::stod(env.substr(env.find("gps_lead_s=") + 11));
  const double fix_seconds = lead + duration - outage_length + 1.0;
  INFO("training pairs " << s.value("training_samples", 0) << ", seconds with a fix " << fix_seconds);
  CHECK(s.value("training_samples", 0) >= 20);
  CHECK(s.value("training_samples", 0) <= fix_seconds);
}

TEST_CASE("e2e: a malformed config is refused with file and line before any device opens", "[e2e][daemon]") {
  Work work;
  REQUIRE(!work.dir.empty());
  const fs::path config = work.dir / "bad.toml";
  std::ofstream(config) << "[audio]\nrate = 48000\n[output]\nkind = \"pty\"\npulses_per_km = -5\n";
  const std::string daemon = quote(kBuild + "/daemon/gearpulsed");
  for (const std::string mode : {"--check-config", ""}) {
    const Result r = run(daemon + " --config " + quote(config.string()) + " " + mode + " 2>&1");
    INFO("mode '" << mode << "': " << r.out);
    CHECK(r.status != 0);
    CHECK(r.out.find(config.string() + ":5") != std::string::npos);
    CHECK(r.out.find("pulses_per_km") != std::string::npos);
  }
  // Broken TOML syntax, not just a bad value.
  std::ofstream(config) << "[audio]\nrate = 48000\ndevice = \"unterminated\n";
  const Result r = run(daemon + " --config " + quote(config.string()) + " 2>&1");
  INFO(r.out);
  CHECK(r.status != 0);
  CHECK(r.out.find(config.string() + ":3") != std::string::npos);
}
