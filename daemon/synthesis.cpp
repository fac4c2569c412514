#include "daemon/synthesis.hpp"

// core/speed_synth.hpp names its source enum gearpulse::SpeedSource, as drivers/speed_source.hpp names
// its GPS interface class: this file includes only the former, the pipeline only the latter.
#include "core/speed_synth.hpp"

namespace gearpulse::daemon {

const char* to_string(Source source) noexcept {
  switch (source) {
    case Source::kGps:
      return "gps";
    case Source::kEngine:
      return "engine";
    case Source::kCoast:
      return "coast";
    case Source::kNone:
      break;
  }
  return "none";
}

namespace {

Source from_core(gearpulse::SpeedSource source) noexcept {
  switch (source) {
    case gearpulse::SpeedSource::kGps:
      return Source::kGps;
    case gearpulse::SpeedSource::kEngine:
      return Source::kEngine;
    case gearpulse::SpeedSource::kCoast:
      return Source::kCoast;
    case gearpulse::SpeedSource::kNone:
      break;
  }
  return Source::kNone;
}

}  // namespace

// The same SpeedSynthesizer `gearpulse replay` runs, stepped live.
struct Synthesis::Impl {
  SpeedSynthesizer synth;
};

Synthesis::Synthesis() : impl_(std::make_unique<Impl>()) {}
Synthesis::~Synthesis() = default;

bool Synthesis::set_model(std::shared_ptr<const GearModel> model) noexcept {
  return impl_->synth.set_model(std::move(model));
}

SynthStep Synthesis::step(double t, double gps_speed, double freq) noexcept {
  const SynthOutput out = impl_->synth.step(t, gps_speed, freq);
  return {out.speed, out.gear, from_core(out.source)};
}

}  // namespace gearpulse::daemon
