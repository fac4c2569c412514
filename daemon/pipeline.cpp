#include "daemon/pipeline.hpp"

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>

#include <spdlog/spdlog.h>

namespace gearpulse::daemon {

// Until the device drivers and the synthesis are wired, the pipeline only keeps its heartbeat and
// reports which links are missing.
struct Pipeline::Impl {
  Impl(const Config& c, ModelHolder& m, TrainingStore& s) : config(c), model(m), store(s) {}
  Config config;
  ModelHolder& model;
  TrainingStore& store;
  std::atomic<double> gps_latency{0.0};
  std::atomic<double> min_snr_db{6.0};
};

Pipeline::Pipeline(const Config& config, ModelHolder& model, TrainingStore& store)
    : impl_(std::make_unique<Impl>(config, model, store)) {
  set_tunables({config.gps.latency, config.tracker.min_snr_db});
}

Pipeline::~Pipeline() {
  stop();
}

void Pipeline::start() {
  spdlog::warn(
      "pipeline: audio capture, tracker, gpsd client, synthesis and pulse output are not built in; "
      "serving status only");
}

void Pipeline::stop() noexcept {}

void Pipeline::set_tunables(const PipelineTunables& tunables) noexcept {
  impl_->gps_latency.store(tunables.gps_latency);
  impl_->min_snr_db.store(tunables.min_snr_db);
}

PipelineSnapshot Pipeline::snapshot() const {
  PipelineSnapshot s;
  s.output_state = impl_->config.output.kind == OutputKind::kNone ? "off" : "error";
  if (impl_->config.output.kind != OutputKind::kNone) s.output_error = "pulse output not built in";
  s.audio_error = "audio capture not built in";
  s.gps_error = "gpsd client not built in";
  s.missing = {"audio", "tracker", "gps", "synthesis", "output"};
  return s;
}

}  // namespace gearpulse::daemon
