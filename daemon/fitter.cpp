#include "daemon/fitter.hpp"

#include "core/estimator.hpp"

namespace gearpulse::daemon {

Retrainer::Fitter make_estimator_fitter() {
  // The default "auto" mode: no priors, the gear count comes from the data, as `gearpulse fit`.
  return [](std::span<const Sample> samples) -> GearModel {
    return fit_gear_model(samples, FitOptions{}).model;
  };
}

}  // namespace gearpulse::daemon
