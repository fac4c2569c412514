#include <catch2/catch.hpp>

#include <memory>
#include <string>

#include "daemon/control_handler.hpp"

using gearpulse::Gear;
using gearpulse::GearModel;
using gearpulse::SpeedSource;
using gearpulse::daemon::Config;
using gearpulse::daemon::GpsState;
using gearpulse::daemon::OutputKind;
using gearpulse::daemon::PipelineSnapshot;
using gearpulse::daemon::status_reply;
using gearpulse::daemon::StatusInputs;
namespace control = gearpulse::control;

namespace {

StatusInputs inputs(const Config& config, const std::string& path, PipelineSnapshot snapshot) {
  return StatusInputs{.config = config,
                      .config_path = path,
                      .pipeline = std::move(snapshot),
                      .model = nullptr,
                      .retrainer = {},
                      .training_samples = 7,
                      .new_samples = 3,
                      .problems = {"training.bin discarded"},
                      .reload_error = "",
                      .restart_pending = {"audio.rate"},
                      .clients = 2,
                      .uptime = 12.5};
}

}  // namespace

TEST_CASE("control: status says what is not available as null and where the output goes") {
  Config config;
  config.output.kind = OutputKind::kGpio;
  config.output.chip = "gpiochip1";
  config.output.line = 5;
  config.gps.host = "gps.local";
  config.gps.port = 2948;
  const std::string path = "/etc/gearpulse/gearpulse.toml";
  PipelineSnapshot p;
  p.speed = 10.0;
  p.source = SpeedSource::kEngine;
  p.gps_state = GpsState::kNoFix;
  p.gps_speed = -1.0;  // never a fix
  p.gps_age = -1.0;
  p.tracker_freq = -1.0;  // not tracked: no SNR either
  p.tracker_snr_db = 4.0;
  p.tracker_turns = 1234;
  p.tracker_late_hops = 56;
  control::StatusReply s = status_reply(inputs(config, path, p));
  CHECK(s.speed_kmh == Approx(36.0));
  CHECK(s.source == "engine");
  CHECK(s.output.kind == "gpio");
  CHECK(s.output.path == "gpiochip1:5");
  CHECK(s.gps.state == "no-fix");
  CHECK(s.gps.server == "gps.local:2948");
  CHECK_FALSE(s.gps.speed.has_value());
  CHECK_FALSE(s.gps.age.has_value());
  CHECK_FALSE(s.tracker.freq.has_value());
  CHECK_FALSE(s.tracker.snr_db.has_value());
  CHECK(s.tracker.turns == 1234);
  CHECK(s.tracker.late_hops == 56);
  CHECK(s.audio.failed_step.empty());  // nothing failed: no step, no attempt
  CHECK(s.audio.open_attempts == 0);
  CHECK_FALSE(s.audio.last_attempt.has_value());
  CHECK(s.model_state == control::ModelState::kLearning);
  CHECK(s.model.problems == std::vector<std::string>{"training.bin discarded"});
  CHECK(s.config.restart_pending == std::vector<std::string>{"audio.rate"});
  CHECK(s.training_samples == 7);
  CHECK(s.model.new_samples == 3);
  CHECK(s.clients == 2);

  config.output.kind = OutputKind::kNone;
  p.gps_speed = 12.0;
  p.gps_age = 0.4;
  p.tracker_freq = 88.0;
  p.audio_state = gearpulse::daemon::AudioState::kRecovering;
  p.audio_error = "ALSA error -5: Input/output error";
  p.audio_failed_step = "read";
  p.audio_open_attempts = 4;
  p.audio_last_attempt = 1.7e9;
  p.audio_reopens = 2;
  s = status_reply(inputs(config, path, p));
  CHECK(s.audio.state == "recovering");
  CHECK(s.audio.error == "ALSA error -5: Input/output error");
  CHECK(s.audio.failed_step == "read");
  CHECK(s.audio.open_attempts == 4);
  CHECK(s.audio.last_attempt == 1.7e9);
  CHECK(s.audio.reopens == 2);
  CHECK_FALSE(s.output.path.has_value());
  CHECK(s.gps.speed == 12.0);
  CHECK(s.gps.age == 0.4);
  CHECK(s.tracker.freq == 88.0);
  CHECK(s.tracker.snr_db == 4.0);
}

TEST_CASE("control: status gives a model's gears, or the reason it has none") {
  const Config config;
  StatusInputs in = inputs(config, "x.toml", {});
  auto ladder = std::make_shared<GearModel>();
  ladder->gears = {Gear{.theta = 0.01, .weight = 0.5, .std_error = 0.001},
                   Gear{.theta = 0.02, .weight = 0.5, .std_error = 0.002}};
  ladder->extra["revs"] = {{{"samples", 40}}, {{"samples", 60}}};
  in.model = ladder;
  control::StatusReply s = status_reply(in);
  CHECK(s.model_state == control::ModelState::kTrained);
  REQUIRE(s.gears.size() == 2);
  CHECK(s.gears[1].gear == 2);
  CHECK(s.gears[1].theta == 0.02);
  REQUIRE(s.model.known_gears.size() == 2);
  CHECK(s.model.known_gears[0].pairs == 40);
  CHECK_FALSE(s.model.reason.has_value());

  // A model file edited by hand: what is not a gear's count of samples reads as none, never an error.
  ladder->extra["revs"] = {1, {{"samples", "many"}}};
  s = status_reply(in);
  REQUIRE(s.model.known_gears.size() == 2);
  CHECK(s.model.known_gears[0].pairs.is_null());
  CHECK(s.model.known_gears[1].pairs.is_null());

  auto none = std::make_shared<GearModel>();
  none->reason = "no gear ladder (automatic or CVT)";
  in.model = none;
  s = status_reply(in);
  CHECK(s.model_state == control::ModelState::kLearning);
  CHECK(s.model.reason == "no gear ladder (automatic or CVT)");
  CHECK(s.gears.empty());
}
