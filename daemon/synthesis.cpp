#include "daemon/synthesis.hpp"

#include <cmath>

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

// Until the gear-tracking synthesizer is built in: GPS speed while fresh; without GPS, the nearest gear's
// theta x frequency if a model exists, else none.
struct Synthesis::Impl {
  std::shared_ptr<const GearModel> model;
  double last_speed = 0.0;
};

Synthesis::Synthesis() : impl_(std::make_unique<Impl>()) {}
Synthesis::~Synthesis() = default;

void Synthesis::set_model(std::shared_ptr<const GearModel> model) noexcept {
  impl_->model = std::move(model);
}

SynthStep Synthesis::step(double, double gps_speed, double freq) noexcept {
  if (std::isfinite(gps_speed)) {
    impl_->last_speed = gps_speed;
    return {gps_speed, 0, Source::kGps};
  }
  const GearModel* m = impl_->model.get();
  if (m && !m->empty() && std::isfinite(freq) && freq > 0) {
    double best = m->gears.front().theta * freq;
    for (const Gear& g : m->gears)
      if (std::abs(g.theta * freq - impl_->last_speed) < std::abs(best - impl_->last_speed))
        best = g.theta * freq;
    impl_->last_speed = best;
    return {best, 0, Source::kEngine};
  }
  return {0.0, 0, Source::kNone};
}

}  // namespace gearpulse::daemon
