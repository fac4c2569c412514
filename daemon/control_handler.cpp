#include "daemon/control_handler.hpp"

#include <algorithm>
#include <cstdint>
#include <string>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "daemon/fitter.hpp"

namespace gearpulse::daemon {
namespace {

std::vector<control::GearRow> gear_rows(const ModelPtr& model) {
  std::vector<control::GearRow> gears;
  if (!model) return gears;
  int index = 1;
  for (const Gear& g : model->gears)
    gears.push_back({.gear = index++, .theta = g.theta, .std_error = g.std_error, .weight = g.weight});
  return gears;
}

// The gears the model knows, with the training pairs on each one's line at its fit (null when the model
// does not say) and whether a refit kept it from the model before (docs/cold-start.md).
std::vector<control::KnownGear> known_gears(const ModelPtr& model) {
  std::vector<control::KnownGear> gears;
  if (!model) return gears;
  const auto revs = model->extra.find("revs");
  const bool counted = revs != model->extra.end() && revs->is_array() && revs->size() == model->gears.size();
  // A model file edited by hand may hold anything there: only a number of samples is reported.
  const auto samples_of = [](const nlohmann::json& gear_revs) -> nlohmann::json {
    if (!gear_revs.is_object()) return nullptr;
    const auto n = gear_revs.find("samples");
    return n != gear_revs.end() && n->is_number() ? *n : nlohmann::json(nullptr);
  };
  const auto kept = model->extra.find(kKeptGears);
  for (std::size_t i = 0; i < model->gears.size(); ++i) {
    const Gear& g = model->gears[i];
    const bool was_kept = kept != model->extra.end() && kept->is_array() &&
                          std::find(kept->begin(), kept->end(), nlohmann::json(g.theta)) != kept->end();
    gears.push_back({.gear = static_cast<int>(i + 1),
                     .theta = g.theta,
                     .std_error = g.std_error,
                     .pairs = counted ? samples_of((*revs)[i]) : nullptr,
                     .kept = was_kept});
  }
  return gears;
}

control::ModelState model_state(const ModelPtr& model) {
  return model && !model->empty() ? control::ModelState::kTrained : control::ModelState::kLearning;
}

}  // namespace

control::StatusReply status_reply(const StatusInputs& in) {
  const PipelineSnapshot& p = in.pipeline;
  const ModelPtr& m = in.model;
  const Retrainer::Status& r = in.retrainer;
  const Config& config = in.config;
  using control::number_if;
  control::StatusReply reply;
  reply.speed = p.speed;
  reply.speed_kmh = p.speed * 3.6;
  reply.speed_sd = p.speed_sd;
  reply.source = source_name(p.source);
  reply.gear = p.gear;
  reply.pulses = p.pulses;
  reply.pulse_frequency = p.pulse_frequency;
  reply.gears = gear_rows(m);
  reply.model_state = model_state(m);
  reply.training_samples = in.training_samples;
  reply.uptime = in.uptime;
  reply.output = {.kind = to_string(config.output.kind),
                  .state = std::string(to_string(p.output_state)),
                  .error = p.output_error,
                  .dropped = p.output_dropped,
                  .unheard = p.output_unheard,
                  .pulses_per_km = config.output.pulses_per_km,
                  .path = std::nullopt};
  if (config.output.kind != OutputKind::kNone) reply.output.path = output_target(config.output);
  reply.gps = {.state = std::string(to_string(p.gps_state)),
               .speed = number_if(p.gps_speed, p.gps_speed >= 0),
               .mode = p.gps_mode,
               .age = number_if(p.gps_age, p.gps_age >= 0),
               .reconnects = p.gps_reconnects,
               .implausible = p.gps_implausible,
               .unmeasured = p.gps_unmeasured,
               .server = fmt::format("{}:{}", config.gps.host, config.gps.port),
               .error = p.gps_error};
  reply.audio = {.state = std::string(to_string(p.audio_state)),
                 .device = config.audio.device,
                 .rate = config.audio.rate,
                 .xruns = p.xruns,
                 .ring_drops = p.ring_drops,
                 .error = p.audio_error,
                 .failed_step = p.audio_failed_step,
                 .open_attempts = p.audio_open_attempts,
                 .last_attempt = number_if(p.audio_last_attempt, p.audio_last_attempt >= 0),
                 .reopens = p.audio_reopens};
  reply.tracker = {.freq = number_if(p.tracker_freq, p.tracker_freq >= 0),
                   .snr_db = number_if(p.tracker_snr_db, p.tracker_freq >= 0),
                   .confident = p.tracker_confident,
                   .turns = p.tracker_turns,
                   .late_hops = p.tracker_late_hops};
  reply.model = {.state = model_state(m),
                 .gears = m ? m->gears.size() : 0,
                 .fit_samples = m ? m->samples : 0,
                 .training_samples = in.training_samples,
                 .new_samples = in.new_samples,
                 .retrain_runs = r.runs,
                 .retrain_busy = r.busy,
                 .last_retrain = number_if(r.last_run_wall, r.runs > 0),
                 .last_result = r.last_result,
                 .reason = std::nullopt,
                 .known_gears = known_gears(m),
                 .learning = {.young = r.young,
                              .moving_time = r.moving_time,
                              .next_refit = number_if(r.next_refit, r.next_refit >= 0.0),
                              .cluster_pairs = r.cluster_pairs,
                              .first_fit_pairs = config.model.learn_cluster_pairs},
                 .problems = {}};
  if (m && m->empty() && !m->reason.empty()) reply.model.reason = m->reason;
  reply.model.problems = in.problems;  // the state directory's: files set aside, failed saves
  if (!r.save_problem.empty()) reply.model.problems.push_back(r.save_problem);  // fits not saved
  reply.config = {
      .file = in.config_path, .reload_error = in.reload_error, .restart_pending = in.restart_pending};
  reply.threads = {.stalled = p.stalled, .missing = p.missing, .realtime_refused = p.realtime_refused};
  reply.clients = in.clients;
  return reply;
}

control::GearsReply gears_reply(const ModelPtr& model, std::size_t training_samples) {
  return {.gears = gear_rows(model),
          .model_state = model_state(model),
          .model = model ? model_to_json(*model) : nlohmann::json(nullptr),
          .training_samples = training_samples};
}

namespace {

// What a rate-limited line adds for the requests it stands for.
std::string since(std::uint64_t more) {
  return more > 0 ? fmt::format(" ({} more such request(s) since the last line)", more) : std::string();
}

}  // namespace

nlohmann::json ControlHandler::operator()(const nlohmann::json& json_request) const {
  const control::Request request = control::parse_request(json_request);
  switch (request.command) {
    case control::Command::kStatus:
      return control::to_json(status_());
    case control::Command::kGears:
      return control::to_json(gears_reply(model_.get(), store_.size()));
    case control::Command::kRetrain:
      retrainer_.request();
      if (std::uint64_t more = 0; request_lines_->allow("retrain", more))
        spdlog::info("control: retrain requested ({} training pairs){}", store_.size(), since(more));
      return control::to_json(control::RetrainReply{.queued = true, .training_samples = store_.size()});
    case control::Command::kResetModel:
      try {
        state_.reset_model(request.keep_samples);
        retrainer_.model_reset(!request.keep_samples);
      } catch (const std::exception& e) {
        throw control::ControlError(e.what());
      }
      if (std::uint64_t more = 0; request_lines_->allow("reset-model", more))
        spdlog::warn("control: model reset{}; pulses follow GPS while the model is learning again{}",
                     request.keep_samples ? " (training pairs kept)" : " and training pairs cleared",
                     since(more));
      return control::to_json(control::ResetReply{.reset = true, .training_samples = store_.size()});
  }
  throw control::ControlError("unknown command");
}

}  // namespace gearpulse::daemon
