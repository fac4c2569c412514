#pragma once
// The conditional density of speed given frequency, paper eq. (6), generalised with a standstill spike:
//   p(v | s) = sum_i alpha_i N(v; theta_i s, theta_i^2 sigma_s^2 + sigma_v^2)
//            + beta_stand * HalfNormal(v; stand_sigma) + beta_clutch * g(v)
// with g a piecewise-constant density over [g_lo, g_hi] (one bin = the paper's uniform g, section 5).
// Shared by the paper and auto estimators: log-likelihood (7), its gradient, EM sufficient statistics.
#include <cstddef>
#include <span>
#include <stop_token>
#include <vector>

#include <Eigen/Dense>

#include "core/slice_runner.hpp"

namespace gearpulse::detail {

struct MixtureData {
  std::vector<double> v;            // m/s
  std::vector<double> s;            // Hz
  std::vector<double> t;            // s, in sample order; may be empty (then no temporal information is used)
  SliceRunner* parallel = nullptr;  // where the passes below run their slices; null: in turn, here
  std::stop_token stop;             // FitOptions::stop: every pass over the data checks it first
  [[nodiscard]] std::size_t size() const noexcept { return v.size(); }
};

struct MixtureParams {
  std::vector<double> theta;  // ascending, eq. (5)
  std::vector<double> alpha;  // gear weights
  double sigma_s = 1.0;
  double sigma_v = 0.1;
  double beta_stand = 0.0;  // standstill spike weight (0 = absent, as in the paper)
  double stand_sigma = 0.1;
  double beta_clutch = 0.0;       // beta of eq. (6)
  std::vector<double> g_density;  // per bin, integrates to 1 over [g_lo, g_hi]
  double g_lo = 0.0;
  double g_hi = 1.0;

  [[nodiscard]] int gears() const noexcept { return static_cast<int>(theta.size()); }
};

// Throws FitCancelled when the fit was asked to stop (every pass over the data calls it first).
void throw_if_stopped(const MixtureData& data);

// From this many samples on, the passes over the data below are split into two slices, one per half, run
// by data.parallel (below it a second thread costs more than it saves).
inline constexpr std::size_t kParallelSamples = 40000;

// Sum over samples of ln p(v_k | s_k), eq. (7).
[[nodiscard]] double log_likelihood(const MixtureData& data, const MixtureParams& p);

// Parameter vector for derivatives: theta_1..theta_M, sigma_s, sigma_v, then (if with_weights) the
// log-weights eta_j of alpha_1..alpha_M, beta_stand (if > 0), relative to beta_clutch (alpha = softmax).
struct GradientLayout {
  int gears = 0;
  bool with_weights = false;
  bool with_stand = false;
  [[nodiscard]] int size() const noexcept {
    return gears + 2 + (with_weights ? gears + (with_stand ? 1 : 0) : 0);
  }
};

// Log-likelihood and its gradient in the layout above.
double log_likelihood_gradient(const MixtureData& data, const MixtureParams& p, const GradientLayout& layout,
                               Eigen::VectorXd& gradient);

// Observed information: minus the Hessian of (7), analytic, one pass over the data.
[[nodiscard]] Eigen::MatrixXd observed_information(const MixtureData& data, const MixtureParams& p,
                                                   const GradientLayout& layout);
// The same by central differences of the analytic gradient (2P passes): a cross-check for tests.
[[nodiscard]] Eigen::MatrixXd observed_information_numeric(const MixtureData& data, const MixtureParams& p,
                                                           const GradientLayout& layout);

// Applies a parameter vector (layout above) onto a copy of p.
[[nodiscard]] MixtureParams with_vector(const MixtureParams& p, const GradientLayout& layout,
                                        const Eigen::VectorXd& x);
[[nodiscard]] Eigen::VectorXd to_vector(const MixtureParams& p, const GradientLayout& layout);

// Sufficient statistics of one E-step (responsibilities summed per component).
struct EStepStats {
  double log_likelihood = 0.0;
  std::vector<double> r;    // per gear: sum of responsibilities
  std::vector<double> rvs;  // sum r v s
  std::vector<double> rss;  // sum r s^2
  std::vector<double> rvv;  // sum r v^2
  double r_stand = 0.0;
  double r_stand_vv = 0.0;
  double r_clutch = 0.0;
  std::vector<double> r_clutch_bins;
  void reset(int gears, std::size_t bins);
  void add(const EStepStats& other);
};

[[nodiscard]] EStepStats e_step(const MixtureData& data, const MixtureParams& p);

// One generalised EM (ECM) update from the statistics: weights, standstill width, g's bins, thetas by
// weighted least squares, then sigma_s and sigma_v by a 2-D minimisation of the expected log-likelihood.
// fixed_weights keeps alpha, beta (paper mode); fixed_g keeps g.
void m_step(const EStepStats& stats, MixtureParams& p, bool fixed_weights, bool fixed_g);

}  // namespace gearpulse::detail
