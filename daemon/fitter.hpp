#pragma once
// The model fit the retrainer runs: the same estimator as `gearpulse fit`.
#include "daemon/retrainer.hpp"

namespace gearpulse::daemon {

[[nodiscard]] Retrainer::Fitter make_estimator_fitter();

}  // namespace gearpulse::daemon
