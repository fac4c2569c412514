// The live chain in-process through real components: ALSA capture from the file plugin fed by a paced
// FIFO, gpsd started by gpsfake, the tracker and the synthesis stepped by the pipeline's own thread.
#include <fcntl.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <vector>

#include <catch2/catch.hpp>

#include "drivers/unique_fd.hpp"
#include "tests/daemon/live_chain.hpp"
#include "tests/daemon/log_lines.hpp"

using namespace std::chrono_literals;
using namespace gearpulse::test;
using gearpulse::SpeedSource;
using gearpulse::daemon::AudioState;
using gearpulse::daemon::GpsState;
using gearpulse::daemon::OutputState;

TEST_CASE(
    "pipeline: with capture periods of half a second the synthesis runs on the engine through an outage") {
  // 4096 frames at 8 kHz: the tracker gets its points in batches about 0.5 s apart, far longer than a
  // hop and a window. Between two batches the synthesis must wait for audio, not step without it.
  LiveChain chain(4096, 48, 0.25);  // about 12 s of GPS
  chain.model.set(one_gear());
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  // GPS and the engine agree on the one gear.
  REQUIRE(wait_for(
      [&] {
        const auto s = pipeline.snapshot();
        return s.source == SpeedSource::kGps && s.gear == 1 && near(s.tracker_freq, kTone, kWander + 0.5);
      },
      20s));
  // gpsfake ends with its log: GPS is lost, the ripple goes on.
  REQUIRE(wait_for([&] { return pipeline.snapshot().source != SpeedSource::kGps; }, 30s));
  // Every look at the outage's first 5 s finds the engine carrying the speed in gear.
  int looks = 0, on_engine = 0, right_speed = 0;
  const auto end = std::chrono::steady_clock::now() + 5s;
  while (std::chrono::steady_clock::now() < end) {
    const auto s = pipeline.snapshot();
    ++looks;
    on_engine += s.source == SpeedSource::kEngine && s.gear == 1;
    right_speed += near(s.speed, kSpeed, kSpeedTol);
    std::this_thread::sleep_for(20ms);
  }
  INFO("looks " << looks);
  CHECK(on_engine == looks);
  CHECK(right_speed == looks);
}

TEST_CASE("pipeline: raising gps.latency at run time keeps training pairs coming") {
  LiveChain chain(512, 80, 0.5);  // about 40 s of GPS
  chain.config.gps.latency = 0.0;
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  gearpulse::daemon::TrainingStore& store = chain.store;
  REQUIRE(wait_for([&] { return pipeline.drain_pairs() > 0; }, 20s));
  // A reload raises the latency close to the most the config accepts: each fix is now matched with the
  // tracker's reading from that long before it was received.
  const double latency = gearpulse::daemon::kMaxGpsLatency - 0.5;
  pipeline.set_tunables({latency, chain.config.tracker.min_snr_db});
  std::this_thread::sleep_for(1s);
  pipeline.drain_pairs();
  const std::size_t before = store.size();
  std::size_t added = 0;
  wait_for(
      [&] {
        added += pipeline.drain_pairs();
        return added >= 5;
      },
      10s);
  CHECK(added >= 5);
  const auto pairs = store.snapshot();
  REQUIRE(pairs.size() >= before + added);
  for (std::size_t i = before; i < pairs.size(); ++i) {
    CHECK(near(pairs[i].speed, kSpeed, 0.01));
    CHECK(near(pairs[i].freq, kTone, kWander + 0.5));
  }
}

// With a decision lag each fix waits for its hops' decided confidence, the lag and a hop longer than without:
// at the most the config accepts (2 s) and no GPS latency, pairs still come, each of the fix's speed and the
// engine's frequency.
TEST_CASE("pipeline: with the longest decision lag training pairs keep coming") {
  LiveChain chain(512, 80, 0.5);  // about 40 s of GPS
  chain.config.gps.latency = 0.0;
  chain.config.tracker.decision_lag = 2.0;
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  gearpulse::daemon::TrainingStore& store = chain.store;
  std::size_t added = 0;
  wait_for(
      [&] {
        added += pipeline.drain_pairs();
        return added >= 5;
      },
      25s);
  CHECK(added >= 5);
  const auto pairs = store.snapshot();
  REQUIRE(pairs.size() >= added);
  for (const auto& pair : pairs) {
    CHECK(near(pair.speed, kSpeed, 0.01));
    CHECK(near(pair.freq, kTone, kWander + 0.5));
  }
}

TEST_CASE(
    "pipeline: audio that freezes (its source stopped) is not taken for an engine nor made into pairs") {
  // The ripple's writer goes away after 6 s and comes back 14 s later: meanwhile the file plugin hands
  // the capture its last period again and again, as a stalled source would.
  constexpr unsigned kPeriod = 512;
  const gearpulse::test::WriterBreak gone{gearpulse::test::WriterBreak::kClose, 6 * kRate / kPeriod, 14s};
  LiveChain chain(kPeriod, 90, 0.5, gone);  // about 45 s of GPS
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  REQUIRE(wait_for([&] { return pipeline.drain_pairs() > 0; }, 20s));
  REQUIRE(wait_for([&] { return pipeline.snapshot().audio_state == AudioState::kFrozen; }, 15s));
  // Fixes already waiting for their window may still be paired; after that, none.
  std::this_thread::sleep_for(3s);
  pipeline.drain_pairs();
  std::size_t while_frozen = 0;
  for (int i = 0; i < 40; ++i) {
    std::this_thread::sleep_for(100ms);
    while_frozen += pipeline.drain_pairs();
    const auto s = pipeline.snapshot();
    CHECK(s.audio_state == AudioState::kFrozen);
    CHECK(s.tracker_freq < 0.0);  // nothing tracked
    CHECK(s.source == SpeedSource::kGps);
  }
  CHECK(while_frozen == 0);
  // The writer is back: the audio runs and pairs come again.
  REQUIRE(wait_for([&] { return pipeline.snapshot().audio_state == AudioState::kRunning; }, 20s));
  CHECK(wait_for([&] { return pipeline.drain_pairs() > 0; }, 10s));
}

TEST_CASE("pipeline: audio that stops coming (the device open, no frames) is stalled, then running again") {
  // The ripple's writer holds the FIFO open and writes nothing for 6 s, 4 s in: the capture waits on the
  // device with nothing to read, as with a card whose pointer stopped.
  constexpr unsigned kPeriod = 512;
  const gearpulse::test::WriterBreak held{gearpulse::test::WriterBreak::kStall, 4 * kRate / kPeriod, 6s};
  LiveChain chain(kPeriod, 60, 0.5, held);  // about 30 s of GPS
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  REQUIRE(wait_for([&] { return pipeline.snapshot().tracker_freq > 0.0; }, 10s));
  REQUIRE(wait_for([&] { return pipeline.snapshot().audio_state == AudioState::kStalled; }, 10s));
  // Nothing tracked while it stalls. The capture says stalled after 2 s without a frame; the tracker
  // thread lets the engine go on its own clock, after its shorter wait for points (about 0.4 s), at a
  // turn a loaded machine can hold up: waited for, within the 4 s the stall is still said.
  CHECK(wait_for([&] { return pipeline.snapshot().tracker_freq < 0.0; }, 3s));
  REQUIRE(wait_for([&] { return pipeline.snapshot().audio_state == AudioState::kRunning; }, 15s));
  CHECK(wait_for([&] { return pipeline.snapshot().tracker_freq > 0.0; }, 10s));
}

TEST_CASE("pipeline: a PTY reader that stops reading is reported, and no longer once it reads again") {
  LiveChain chain(512, 60, 0.5);  // about 30 s of GPS at kSpeed
  const auto link = chain.dir / "pulse";
  chain.config.output.kind = gearpulse::daemon::OutputKind::kPty;
  chain.config.output.path = link.string();
  // 1600 pulses a second at kSpeed: a reader that does not read has its queue full within seconds.
  chain.config.output.pulses_per_km = 100000.0;
  chain.config.output.max_frequency = 2000.0;
  chain.config.output.pulse_width = 0.0002;
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  REQUIRE(wait_for([&] { return std::filesystem::is_symlink(link); }, 10s));
  gearpulse::UniqueFd reader(::open(link.c_str(), O_RDONLY | O_NOCTTY | O_NONBLOCK));  // never read
  REQUIRE(reader);
  const int fd = reader.get();
  REQUIRE(wait_for([&] { return pipeline.snapshot().source == SpeedSource::kGps; }, 20s));
  CHECK(pipeline.snapshot().output_state == OutputState::kOk);
  REQUIRE(wait_for([&] { return pipeline.snapshot().output_state == OutputState::kReaderBehind; }, 15s));
  CHECK(pipeline.snapshot().output_dropped > 0);
  // The reader reads again: within the 5 s the state lasts after the last dropped pulse, it is ok.
  char buf[4096];
  const bool ok = wait_for(
      [&] {
        while (::read(fd, buf, sizeof buf) > 0) {
        }
        return pipeline.snapshot().output_state == OutputState::kOk;
      },
      10s);
  CHECK(ok);
}

TEST_CASE("pipeline: pulses with no PTY reader are counted as unheard and the output says no-reader") {
  LiveChain chain(512, 60, 0.5);  // about 30 s of GPS at kSpeed
  const auto link = chain.dir / "pulse";
  chain.config.output.kind = gearpulse::daemon::OutputKind::kPty;
  chain.config.output.path = link.string();
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  REQUIRE(wait_for([&] { return std::filesystem::is_symlink(link); }, 10s));
  REQUIRE(wait_for([&] { return pipeline.snapshot().source == SpeedSource::kGps; }, 20s));
  // Pulses go out at kSpeed, to nobody.
  REQUIRE(wait_for([&] { return pipeline.snapshot().output_unheard > 10; }, 10s));
  const auto alone = pipeline.snapshot();
  CHECK(alone.output_state == OutputState::kNoReader);
  CHECK(alone.output_unheard <= alone.pulses);
  CHECK(alone.output_dropped == 0);
  // A reader comes: the state is ok and the count stops (a reader that reads hears every pulse).
  gearpulse::UniqueFd reader(::open(link.c_str(), O_RDONLY | O_NOCTTY | O_NONBLOCK));
  REQUIRE(reader);
  const int fd = reader.get();
  REQUIRE(wait_for([&] { return pipeline.snapshot().output_state == OutputState::kOk; }, 5s));
  // A pulse the pulse thread began before the reader came may still be counted unheard: the next pulse
  // counted comes after it.
  const std::uint64_t seen_at = pipeline.snapshot().pulses;
  REQUIRE(wait_for([&] { return pipeline.snapshot().pulses > seen_at; }, 5s));
  const std::uint64_t unheard = pipeline.snapshot().output_unheard;
  const std::uint64_t pulses = pipeline.snapshot().pulses;
  char buf[4096];
  CHECK(wait_for(
      [&] {
        while (::read(fd, buf, sizeof buf) > 0) {
        }
        return pipeline.snapshot().pulses > pulses + 10;
      },
      10s));
  CHECK(pipeline.snapshot().output_unheard == unheard);
  reader.reset();  // the reader leaves
  CHECK(wait_for([&] { return pipeline.snapshot().output_state == OutputState::kNoReader; }, 5s));
}

// A sound card that fails while capturing, again and again, is then gone, and is back later. The file
// plugin writes what it captures to its sink, here first a link to /dev/full: each open reads a little,
// then a read fails with -EIO (a loose connector: lost and back several times a second). Then the infile
// is removed (no device to open), then put back with the sink turned to /dev/null.
TEST_CASE("pipeline: a sound card lost while capturing is recovering with its error, and running once back") {
  gearpulse::test::LogLines log;
  GpsOnly chain;
  const auto infile = chain.dir / "ripple.raw", sink = chain.dir / "sink";
  gearpulse::test::write_raw(infile, ripple(60.0));
  std::filesystem::create_symlink("/dev/full", sink);
  gearpulse::test::use_alsa_config(chain.dir, "unplugged", infile, sink);
  chain.config.audio.device = "unplugged";
  chain.config.audio.rate = kRate;
  chain.config.audio.format = "S16_LE";
  chain.config.audio.period_frames = 512;
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  REQUIRE(wait_for([&] { return pipeline.snapshot().audio_state == AudioState::kRecovering; }, 10s));
  // Lost and back several times a second: said at most once each way, not at every time.
  constexpr std::string_view kLost = "audio: capture from unplugged interrupted (ALSA error ";
  constexpr std::string_view kBack = "audio: capture from unplugged resumed";
  std::this_thread::sleep_for(3s);
  pipeline.service();  // the main thread's chore: it says what the tracker thread posted
  CHECK(log.count(kLost) <= 1);
  CHECK(log.count(kBack) <= 1);
  std::filesystem::rename(infile, chain.dir / "unplugged.raw");
  REQUIRE(wait_for(
      [&] { return pipeline.snapshot().audio_error == "ALSA error -2: No such file or directory"; }, 10s));
  for (int i = 0; i < 10; ++i) {
    std::this_thread::sleep_for(50ms);
    const auto s = pipeline.snapshot();
    CHECK(s.audio_state == AudioState::kRecovering);
    CHECK_FALSE(s.audio_error.empty());
  }
  // Where it fails and how long it has been tried, as status shows it: at the open, attempt after
  // attempt, the last one just now.
  const auto gone = pipeline.snapshot();
  CHECK(gone.audio_failed_step == "open");
  CHECK(gone.audio_open_attempts >= 1);
  CHECK(gone.audio_last_attempt > 0.0);
  CHECK(gone.audio_last_attempt <= gearpulse::wall_now());
  CHECK(gone.audio_reopens >= 1);  // the flaps before it was gone
  REQUIRE(wait_for(
      [&] {
        const auto s = pipeline.snapshot();
        return s.audio_open_attempts > gone.audio_open_attempts &&
               s.audio_last_attempt > gone.audio_last_attempt;
      },
      10s));
  std::filesystem::remove(sink);
  std::filesystem::create_symlink("/dev/null", sink);
  std::filesystem::rename(chain.dir / "unplugged.raw", infile);
  REQUIRE(wait_for(
      [&] {
        const auto s = pipeline.snapshot();
        return s.audio_state == AudioState::kRunning && near(s.tracker_freq, kTone, kWander + 0.5);
      },
      20s));
  const auto back = pipeline.snapshot();
  CHECK(back.audio_error.empty());
  CHECK(back.audio_failed_step.empty());
  CHECK(back.audio_open_attempts == 0);
  CHECK(back.audio_last_attempt < 0.0);
  CHECK(back.audio_reopens > gone.audio_reopens);
  // The journal said it was lost (a flap or the loss after them) and, as often, that it was back. The
  // tracker thread posts "resumed" at its look at the capture after the turn that tracked the engine, so
  // the status can say running before the note is there for service() to say.
  CHECK(wait_for(
      [&] {
        pipeline.service();
        return log.count(kBack) == log.count(kLost);
      },
      5s));
  CHECK(log.count(kLost) >= 1);
  CHECK(log.count(kBack) == log.count(kLost));
}

// A sound card that is not there when the daemon starts (its PCM fails to open: the file plugin's infile
// is missing) is retried; status says the open fails, how often it was tried and when last, and nothing
// of it once the card is there.
TEST_CASE(
    "pipeline: a sound card absent at start is retrying at its open, and running with no fault once there") {
  GpsOnly chain;
  const auto infile = chain.dir / "ripple.raw";
  gearpulse::test::use_alsa_config(chain.dir, "late", infile);
  chain.config.audio.device = "late";
  chain.config.audio.rate = kRate;
  chain.config.audio.format = "S16_LE";
  chain.config.audio.period_frames = 512;
  const double started = gearpulse::wall_now();
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  // Retried with a delay that doubles from 0.5 s: a second attempt within a few seconds.
  REQUIRE(wait_for([&] { return pipeline.snapshot().audio_open_attempts >= 2; }, 20s));
  const auto absent = pipeline.snapshot();
  CHECK(absent.audio_state == AudioState::kRetrying);
  CHECK(absent.audio_failed_step == "open");
  CHECK(absent.audio_error.find("cannot open") != std::string::npos);
  CHECK(absent.audio_last_attempt >= started);
  CHECK(absent.audio_last_attempt <= gearpulse::wall_now());
  gearpulse::test::write_raw(chain.dir / "next.raw", ripple(60.0));
  std::filesystem::rename(chain.dir / "next.raw", infile);
  REQUIRE(wait_for([&] { return pipeline.snapshot().audio_state == AudioState::kRunning; }, 30s));
  const auto there = pipeline.snapshot();
  CHECK(there.audio_error.empty());
  CHECK(there.audio_failed_step.empty());
  CHECK(there.audio_open_attempts == 0);
  CHECK(there.audio_last_attempt < 0.0);
  CHECK(there.audio_reopens == 0);
}

// The status a user reads after gpsd comes up late and after it restarts: the connection's old error is
// gone once connected, and only connections after the first count as reconnects.
TEST_CASE(
    "pipeline: gpsd starting late is no reconnect and leaves no error, and a restart is one reconnect") {
  GpsOnly chain;
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  REQUIRE(wait_for([&] { return !pipeline.snapshot().gps_error.empty(); }, 10s));  // gpsd absent
  const std::vector<double> speeds(40, 12.5);
  const auto fix = [&] { return pipeline.snapshot().gps_state == GpsState::kFix; };
  auto fake = chain.gpsd(speeds, 0.1);
  if (!wait_for(fix, 20s)) FAIL("no fix: " << fake->describe());
  auto s = pipeline.snapshot();
  CHECK(s.gps_error.empty());
  CHECK(s.gps_reconnects == 0);
  CHECK(near(s.gps_speed, 12.5, 0.01));
  fake->kill();
  REQUIRE(wait_for([&] { return pipeline.snapshot().gps_state == GpsState::kDisconnected; }, 10s));
  CHECK_FALSE(pipeline.snapshot().gps_error.empty());
  fake = chain.gpsd(speeds, 0.1);
  if (!wait_for(fix, 20s)) FAIL("no fix after the restart: " << fake->describe());
  s = pipeline.snapshot();
  CHECK(s.gps_error.empty());
  CHECK(s.gps_reconnects == 1);
}

// A receiver that goes quiet (gpsd up and connected, no reports) leaves its last fix as the newest
// report: it must stop counting as a fix after gps.timeout, not stay "fix" for as long as gpsd is up.
TEST_CASE("pipeline: a receiver that goes quiet is no fix after gps.timeout and one that resumes is a fix") {
  GpsOnly chain;
  chain.config.gps.timeout = 1.0;
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  auto fake = chain.gpsd(std::vector<double>(40, 9.0), 0.1);
  if (!wait_for([&] { return pipeline.snapshot().gps_state == GpsState::kFix; }, 20s))
    FAIL("no fix: " << fake->describe());
  fake->pause();
  // gps.timeout (1 s) after the last report; gpsd stays up and quiet until resumed, so a bound of 10 s
  // still tells the timeout from "a fix for as long as gpsd is up", with room for a loaded machine.
  REQUIRE(wait_for([&] { return pipeline.snapshot().gps_state != GpsState::kFix; }, 10s));
  const auto quiet = pipeline.snapshot();
  CHECK(quiet.gps_state == GpsState::kNoFix);
  CHECK(quiet.gps_age >= 1.0);
  CHECK(near(quiet.gps_speed, 9.0, 0.01));
  fake->resume();
  CHECK(wait_for([&] { return pipeline.snapshot().gps_state == GpsState::kFix; }, 10s));
}

// Through an outage gpsd goes on reporting, without a fix: the status keeps the speed of the last fix and
// says how long ago it was, which is how long the pulses have run without GPS.
TEST_CASE("pipeline: through a GPS outage the status keeps the last fix's speed and its growing age") {
  GpsOnly chain;
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  // 5 s of fixes, then 8 s without, at 0.2 s per epoch, repeated: a fix phase long enough to be seen by a
  // client that connects late on a loaded machine (2 s of it was missed under a sanitizer build).
  std::vector<double> speeds(25, 14.0);
  speeds.resize(65, std::nan(""));
  auto fake = chain.gpsd(speeds, 0.2);
  REQUIRE(wait_for([&] { return pipeline.snapshot().gps_state == GpsState::kFix; }, 30s));
  REQUIRE(wait_for([&] { return pipeline.snapshot().gps_mode == 1; }, 15s));  // reports without a fix
  REQUIRE(wait_for([&] { return pipeline.snapshot().gps_age > 2.0; }, 10s));
  const auto s = pipeline.snapshot();
  CHECK(s.gps_state == GpsState::kNoFix);
  CHECK(s.gps_mode == 1);
  CHECK(near(s.gps_speed, 14.0, 0.01));
}

// Below output.min_frequency the pulse train does not run: the status says 0 Hz, as the pulses show,
// not the frequency the speed would have.
TEST_CASE("pipeline: a speed whose pulses would be below output.min_frequency shows 0 Hz and sends none") {
  GpsOnly chain;
  chain.config.output.pulses_per_km = 1000.0;  // 12.5 m/s: 12.5 Hz
  chain.config.output.min_frequency = 20.0;
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  auto fake = chain.gpsd(std::vector<double>(40, 12.5), 0.1);
  REQUIRE(wait_for([&] { return near(pipeline.snapshot().speed, 12.5, 0.1); }, 20s));
  std::this_thread::sleep_for(500ms);
  const auto s = pipeline.snapshot();
  CHECK(s.pulse_frequency == 0.0);
  CHECK(s.pulses == 0);
}
