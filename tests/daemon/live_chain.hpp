#pragma once
// The live chains the pipeline tests run through real components: LiveChain, ALSA capture from the file
// plugin fed by a paced FIFO of the lighter's ripple and gpsd started by gpsfake; GpsOnly, the pipeline
// with no sound card and gpsd started by the test.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <vector>

#include <catch2/catch.hpp>

#include "daemon/pipeline.hpp"
#include "tests/drivers/alsa_fifo.hpp"
#include "tests/drivers/gpsfake.hpp"
#include "tests/test_util.hpp"
#include "tools/sim/lighter_signal.hpp"
#include "tools/sim/nmea.hpp"

namespace gearpulse::test {

inline constexpr unsigned kRate = 8000;
inline constexpr double kTone = 80.0;   // Hz: the ripple, inside the tracker's default band
inline constexpr double kWander = 1.5;  // Hz: revs wander (a line fixed to the hertz is other equipment's)
inline constexpr double kTheta = 0.2;   // (m/s)/Hz of the one gear
inline constexpr double kSpeed = 16.0;  // m/s: the speed GPS reports, kTheta x kTone
inline constexpr double kSpeedTol = kTheta * kWander + 0.05 * kSpeed;

// `seconds` of the lighter's ripple around kTone, as the simulator makes it, in S16.
inline std::vector<std::int16_t> ripple(double seconds) {
  gearpulse::sim::LighterSignalConfig g;
  g.sample_rate_hz = kRate;
  g.amplitude = 0.2;
  g.snr_db = 20.0;
  g.seed = 5;
  const auto x = gearpulse::sim::make_lighter_signal(
      g, [](double t) { return kTone + kWander * std::sin(2.0 * M_PI * t / 6.0); }, seconds);
  std::vector<std::int16_t> out(x.size());
  for (std::size_t i = 0; i < x.size(); ++i)
    out[i] = static_cast<std::int16_t>(std::lround(std::clamp(x[i], -1.0f, 1.0f) * 32767.0f));
  return out;
}

// A model of one gear that turns kTone into kSpeed.
inline std::shared_ptr<const gearpulse::GearModel> one_gear() {
  auto m = std::make_shared<gearpulse::GearModel>();
  m->gears = {{kTheta, 1.0, 0.0}};
  m->sigma_speed = 0.3;
  m->sigma_freq = 0.5;
  m->outlier_weight = 0.1;
  m->method = "auto";
  return m;
}

// GPS at kSpeed for `epochs` 1 Hz epochs, played at `cycle` s each, then gone (gpsfake ends with its log).
struct Gps {
  TempDir dir;
  int port = gearpulse::test::free_port();
  std::unique_ptr<GpsFake> fake;
  Gps(std::size_t epochs, double cycle) {
    const std::vector<double> speeds(epochs, kSpeed);
    const auto log = dir / "drive.nmea";
    gearpulse::sim::write_nmea_log(log, gearpulse::sim::epochs_at_1hz(speeds));
    fake = std::make_unique<GpsFake>(log, port, cycle, true);
  }
};

// The chain under test: ripple fed at `period` frames per write, GPS at kSpeed for `epochs` epochs, and
// the pipeline over them. Stopped before its feeder, so the capture's blocking read always returns.
struct LiveChain {
  TempDir dir;
  std::filesystem::path fifo = gearpulse::test::make_paced_pcm(dir);
  FifoFeeder feeder;
  Gps gps;
  gearpulse::daemon::ModelHolder model;
  gearpulse::daemon::TrainingStore store{3600.0, 100000};
  gearpulse::daemon::Config config;
  std::unique_ptr<gearpulse::daemon::Pipeline> pipeline;

  LiveChain(unsigned period, std::size_t epochs, double cycle, gearpulse::test::WriterBreak pause = {})
      : feeder(fifo, ripple(60.0), period, kRate, pause), gps(epochs, cycle) {
    REQUIRE(GpsFake::wait_listening(gps.port, std::chrono::seconds(10)));
    config.audio.device = "paced";
    config.audio.rate = kRate;
    config.audio.format = "S16_LE";
    config.audio.period_frames = period;
    config.gps.port = static_cast<unsigned>(gps.port);
    config.output.kind = gearpulse::daemon::OutputKind::kNone;
    config.model.state_dir = dir.path().string();
    config.log.level = "off";
  }
  ~LiveChain() {
    if (pipeline) pipeline->stop();
  }
  LiveChain(const LiveChain&) = delete;
  LiveChain& operator=(const LiveChain&) = delete;

  // Starts the pipeline and, once its capture runs, the feeder.
  gearpulse::daemon::Pipeline& start() {
    pipeline = std::make_unique<gearpulse::daemon::Pipeline>(config, model, store);
    pipeline->start();
    REQUIRE(
        wait_for([&] { return pipeline->snapshot().audio_state == gearpulse::daemon::AudioState::kRunning; },
                 std::chrono::seconds(10)));
    feeder.go();
    return *pipeline;
  }
};

inline bool near(double x, double want, double tol) {
  return std::abs(x - want) <= tol;
}

// The pipeline on GPS alone (no sound card: speed follows GPS), gpsd to be started by the test at `port`.
struct GpsOnly {
  TempDir dir;
  int port = gearpulse::test::free_port();
  gearpulse::daemon::ModelHolder model;
  gearpulse::daemon::TrainingStore store{3600.0, 1000};
  gearpulse::daemon::Config config;
  std::unique_ptr<gearpulse::daemon::Pipeline> pipeline;

  GpsOnly() {
    config.audio.device = "gearpulse_test_no_such_pcm";
    config.gps.port = static_cast<unsigned>(port);
    config.output.kind = gearpulse::daemon::OutputKind::kNone;
    config.model.state_dir = dir.path().string();
    config.log.level = "off";
  }
  ~GpsOnly() {
    if (pipeline) pipeline->stop();
  }
  GpsOnly(const GpsOnly&) = delete;
  GpsOnly& operator=(const GpsOnly&) = delete;

  gearpulse::daemon::Pipeline& start() {
    pipeline = std::make_unique<gearpulse::daemon::Pipeline>(config, model, store);
    pipeline->start();
    return *pipeline;
  }
  // gpsfake playing `speeds` at 1 Hz of log time (NaN = no fix), `cycle` s per epoch, repeated.
  std::unique_ptr<GpsFake> gpsd(const std::vector<double>& speeds, double cycle) {
    const auto log = dir / "drive.nmea";
    gearpulse::sim::write_nmea_log(log, gearpulse::sim::epochs_at_1hz(speeds));
    return std::make_unique<GpsFake>(log, port, cycle, false);
  }
};

}  // namespace gearpulse::test
