#pragma once
// Pieces the auto fit's translation units share (not part of the public API): the candidate ladders and
// the judge of their physics (auto_candidates.cpp), the EM and BIC of the driver (auto_estimator.cpp), the
// completion of the chosen ladder (auto_ladder_completion.cpp) and the speed channel's lag search
// (auto_lag_search.cpp).
#include <cmath>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "core/estimator_internal.hpp"

namespace gearpulse::detail {

inline constexpr int kEmIterations = 120;
inline constexpr std::size_t kMinMovingSamples = 30;  // moving samples a fit needs at least

struct Candidate {
  MixtureParams params;
  double log_likelihood = -INFINITY;
  double bic = INFINITY;
};

// What the physics of a gearbox asks of a fitted ladder, beyond the likelihood.
struct LadderCheck {
  int offender = -1;  // component to drop first, -1 if the ladder is plausible
  std::string reason;
};

class LadderJudge {
 public:
  LadderJudge(const MixtureData& work, std::size_t total_samples, std::vector<double> steady_log_ratios,
              std::vector<double> moving_log_ratios, std::vector<double> octave_log_ratios);

  // Hz: the idle frequency of the standstill samples; 0 when the log has too few of them.
  double idle_freq() const { return idle_freq_; }

  LadderCheck check(const MixtureParams& p) const;

 private:
  static std::size_t count_in(const std::vector<double>& sorted, double lo, double hi);
  std::size_t count_in(double lo, double hi) const;
  double steady_support(double centre, double half_width) const;
  bool valley_between(double a, double b) const;
  static std::optional<bool> valley_in(const std::vector<double>& sorted, double a, double b);

  struct FreqSpread {
    double p10 = 0.0;  // Hz
    double median = 0.0;
    double p90 = 0.0;
    double speed_median = 0.0;  // m/s
  };

  FreqSpread freq_spread(const MixtureParams& p, int gear) const;

  const MixtureData& work_;
  std::size_t total_;
  std::vector<double> log_ratios_;
  std::vector<double> moving_;
  std::vector<double> octave_;
  double idle_freq_ = 0.0;
};

// Candidate gear scales and the samples that show them (auto_candidates.cpp).
std::vector<double> steady_log_ratios(const MixtureData& all, bool& timed);
std::vector<double> octave_log_ratios(const MixtureData& all);
std::vector<double> candidate_scales(const std::vector<double>& log_ratios, std::size_t limit);

// EM and BIC (auto_estimator.cpp).
double run_em(const MixtureData& data, MixtureParams& p, int max_iter, double tol, bool final_value = true);
MixtureParams initial_params(const MixtureData& data, const std::vector<double>& log_ratios, double vmax);
double bic_of(double log_likelihood, int gears, std::size_t n);

// The chosen ladder completed (auto_ladder_completion.cpp).
Candidate single_cluster(const MixtureData& work, const std::vector<double>& steady, const LadderJudge& judge,
                         double vmax);
void record_lower_gears(const std::vector<double>& largest, GearModel& fitted);
Candidate with_first_gear(const Candidate& best, const std::vector<Candidate>& plausible, double idle_freq);

// The speed channel's lag against engine speed (auto_lag_search.cpp).
struct Aligned {
  MixtureData data;
  double lag = 0.0;  // s: the speed paired with engine speed at t is the one logged at t + lag
};
Aligned aligned_channels(const MixtureData& all);

}  // namespace gearpulse::detail
