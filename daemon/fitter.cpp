#include "daemon/fitter.hpp"

#include <stdexcept>

namespace gearpulse::daemon {

Retrainer::Fitter make_estimator_fitter() {
  return [](std::span<const Sample>) -> GearModel {
    throw std::runtime_error("the gear-scale estimator is not built into this daemon");
  };
}

}  // namespace gearpulse::daemon
