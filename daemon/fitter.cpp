#include "daemon/fitter.hpp"

#include "core/estimator.hpp"
#include "drivers/thread_slice_runner.hpp"

namespace gearpulse::daemon {

Retrainer::Fitter make_estimator_fitter() {
  // The default "auto" mode: no priors, the gear count comes from the data, as `gearpulse fit`; a large
  // store's passes in two threads (the retrainer's thread runs at the lowest priority, so the second
  // core's share comes from idle time; the threads inherit that priority).
  return [](std::span<const Sample> samples) -> GearModel {
    ThreadSliceRunner threads;
    FitOptions options;
    options.parallel = &threads;
    return fit_gear_model(samples, options).model;
  };
}

}  // namespace gearpulse::daemon
