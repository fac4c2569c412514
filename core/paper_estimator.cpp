// The paper's estimator, faithfully: fixed weights (Table 2), uniform g over the speed range, samples
// slower than 2 sigma_v dropped (section 5), initialisation (11)-(16), then the constrained ML (9).
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

#include <nlopt.hpp>

#include "core/estimator_internal.hpp"

namespace gearpulse::detail {
namespace {

// Table 2: alpha_1..alpha_5 = 0.05, 0.1, 0.1, 0.3, 0.4 and beta = 0.1.
constexpr double kTable2Alpha[5] = {0.05, 0.1, 0.1, 0.3, 0.4};
constexpr double kTable2Beta = 0.1;
constexpr double kTable2DM = 0.95;        // d_M of the set kappa_M
constexpr double kTable2DPercent = 10.0;  // d% of the sigma initialisation

// For M != 5 the Table 2 profile is resampled: gear i of M takes the Table 2 weight at the same relative
// position (i - 0.5) / M (piecewise linear between the five values), then all alphas are scaled to sum to
// 1 - beta. For M = 5 this is Table 2 exactly.
std::vector<double> table2_alphas(int m) {
  std::vector<double> alpha(static_cast<std::size_t>(m));
  double sum = 0.0;
  for (int i = 0; i < m; ++i) {
    const double x = (i + 0.5) / m * 5.0 - 0.5;  // position on the 0..4 index of Table 2
    const double xc = std::clamp(x, 0.0, 4.0);
    const int lo = std::min(static_cast<int>(xc), 3);
    const double w = xc - lo;
    alpha[static_cast<std::size_t>(i)] = (1 - w) * kTable2Alpha[lo] + w * kTable2Alpha[lo + 1];
    sum += alpha[static_cast<std::size_t>(i)];
  }
  for (double& a : alpha)
    a *= (1.0 - kTable2Beta) / sum;
  return alpha;
}

double percentile(std::vector<double> values, double pct) {
  if (values.empty()) return 0.0;
  const double pos = pct / 100.0 * static_cast<double>(values.size() - 1);
  const auto k = static_cast<std::size_t>(pos);
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return values[k];
}

// step(i) = theta_{i+1} / theta_i for i = 0..M-2 (0-based lower gear), from the CLI's top-down list.
double prior_step(const std::vector<double>& ratios, int lower_gear) {
  const int m = static_cast<int>(ratios.size()) + 1;
  return ratios[static_cast<std::size_t>(m - 2 - lower_gear)];
}

// Lower gears follow from gear `from` by the prior steps, eqs. (14)-(16).
void tie_lower(MixtureParams& p, const std::vector<double>& ratios, int from) {
  for (int j = from - 1; j >= 0; --j)
    p.theta[j] = p.theta[j + 1] / prior_step(ratios, j);
}

// A local, bounded quasi-Newton minimisation of f (value and gradient) from x (NLopt L-BFGS); x keeps the
// best point reached when NLopt stops early (roundoff-limited stops still carry a usable x).
template <class F>
void minimise_local(const MixtureData& data, F& f, std::vector<double>& x, const std::vector<double>& lower,
                    const std::vector<double>& upper) {
  for (std::size_t k = 0; k < x.size(); ++k)
    x[k] = std::clamp(x[k], lower[k], upper[k]);
  nlopt::opt opt(nlopt::LD_LBFGS, static_cast<unsigned>(x.size()));
  opt.set_lower_bounds(lower);
  opt.set_upper_bounds(upper);
  auto thunk = [](const std::vector<double>& y, std::vector<double>& grad, void* ctx) {
    return (*static_cast<F*>(ctx))(y, grad);
  };
  opt.set_min_objective(thunk, &f);
  opt.set_ftol_rel(1e-12);
  opt.set_xtol_rel(1e-9);
  opt.set_maxeval(500);
  double val = 0.0;
  try {
    opt.optimize(x, val);
  } catch (const std::exception&) {
    // NLopt ends every early stop with an exception of its own, a cancelled fit's included (it does not
    // carry the type through): that one is thrown again below.
  }
  throw_if_stopped(data);
}

}  // namespace

GearModel fit_paper(const MixtureData& all, const std::vector<double>& ratios) {
  const int m = static_cast<int>(ratios.size()) + 1;
  GearModel model;
  model.method = "paper";
  if (all.size() < static_cast<std::size_t>(4 * m)) {
    model.reason = "too few samples with both speed and frequency";
    return model;
  }
  // (11)-(12): the top gear from the samples near the maximum speed, by the median ratio.
  const double vmax = *std::max_element(all.v.begin(), all.v.end());
  if (!(vmax > 0.0)) {
    model.reason = "the vehicle never moves in this log";
    return model;
  }
  std::vector<double> ratio_top;
  std::vector<std::size_t> kappa;
  for (std::size_t k = 0; k < all.size(); ++k) {
    if (all.v[k] > kTable2DM * vmax && all.s[k] > 0.0) {
      kappa.push_back(k);
      ratio_top.push_back(all.v[k] / all.s[k]);
    }
  }
  if (kappa.empty()) {
    model.reason = "no usable samples near the maximum speed";
    return model;
  }
  MixtureParams p;
  p.theta.assign(static_cast<std::size_t>(m), 0.0);
  p.theta.back() = percentile(ratio_top, 50.0);
  // sigma_s = sigma_v = |nu_d%(residuals)| / sqrt(1 + theta_M^2): the d-th percentile of the signed
  // residuals is negative, its magnitude is the scale the paper intends.
  std::vector<double> residuals;
  for (std::size_t k : kappa)
    residuals.push_back(all.v[k] - p.theta.back() * all.s[k]);
  double sigma0 =
      std::abs(percentile(residuals, kTable2DPercent)) / std::sqrt(1.0 + p.theta.back() * p.theta.back());
  if (!(sigma0 > 1e-4)) sigma0 = 1e-2 * std::max(vmax, 1.0);
  p.sigma_s = p.sigma_v = sigma0;
  tie_lower(p, ratios, m - 1);
  p.alpha = table2_alphas(m);
  p.beta_clutch = kTable2Beta;

  // Section 5: drop v < 2 sigma_v (with the initial sigma_v); g uniform over the remaining speed range.
  MixtureData data;
  data.parallel = all.parallel;
  data.stop = all.stop;
  for (std::size_t k = 0; k < all.size(); ++k) {
    if (all.v[k] >= 2.0 * p.sigma_v) {
      data.v.push_back(all.v[k]);
      data.s.push_back(all.s[k]);
    }
  }
  if (data.size() < static_cast<std::size_t>(4 * m)) {
    model.reason = "too few moving samples";
    return model;
  }
  p.g_lo = *std::min_element(data.v.begin(), data.v.end());
  p.g_hi = *std::max_element(data.v.begin(), data.v.end());
  if (!(p.g_hi > p.g_lo)) p.g_hi = p.g_lo + 1.0;
  p.g_density = {1.0 / (p.g_hi - p.g_lo)};

  // (15) and (16) are local searches from the heuristic initial values, as the paper's interior-point
  // method is: the likelihood is multimodal in theta (a gear's Gaussian can move onto a neighbour's
  // cluster), and the initialisation exists to start in the right basin. Gradients are analytic; with
  // the lower gears tied by the prior steps, d theta_j / d ln theta_i = theta_j for every j <= i.
  const GradientLayout layout{m, false, false};
  const auto tied_gradient = [&](const MixtureParams& q, int top, Eigen::VectorXd& g) {
    const double ll = log_likelihood_gradient(data, q, layout, g);
    double d = 0.0;
    for (int j = 0; j <= top; ++j)
      d += g[j] * q.theta[static_cast<std::size_t>(j)];
    return std::pair{ll, d};
  };
  // (15): theta_M, sigma_v, sigma_s with the lower gears tied to theta_M by the prior ratios.
  {
    std::vector<double> x = {std::log(p.theta.back()), std::log(p.sigma_s), std::log(p.sigma_v)};
    auto f = [&](const std::vector<double>& y, std::vector<double>& grad) {
      MixtureParams q = p;
      q.theta.back() = std::exp(y[0]);
      q.sigma_s = std::exp(y[1]);
      q.sigma_v = std::exp(y[2]);
      tie_lower(q, ratios, m - 1);
      Eigen::VectorXd g;
      const auto [ll, d_theta] = tied_gradient(q, m - 1, g);
      if (!grad.empty()) grad = {-d_theta, -g[m] * q.sigma_s, -g[m + 1] * q.sigma_v};
      return -ll;
    };
    minimise_local(data, f, x, {x[0] - std::log(1.5), x[1] - 8.0, x[2] - 8.0},
                   {x[0] + std::log(1.5), x[1] + 5.0, x[2] + 5.0});
    p.theta.back() = std::exp(x[0]);
    p.sigma_s = std::exp(x[1]);
    p.sigma_v = std::exp(x[2]);
    tie_lower(p, ratios, m - 1);
  }
  // (16): from high to low gears, one theta at a time, starting where the prior step from the gear above
  // puts it and kept between its neighbours (the one below at its prior position, the one above as
  // refined), the lower gears following.
  for (int i = m - 2; i >= 0; --i) {
    const double upper = p.theta[static_cast<std::size_t>(i + 1)];
    const double lower = upper / (prior_step(ratios, i) * (i > 0 ? prior_step(ratios, i - 1) : 1.5));
    std::vector<double> x = {std::log(p.theta[static_cast<std::size_t>(i)])};
    auto f = [&](const std::vector<double>& y, std::vector<double>& grad) {
      MixtureParams q = p;
      q.theta[static_cast<std::size_t>(i)] = std::exp(y[0]);
      tie_lower(q, ratios, i);
      Eigen::VectorXd g;
      const auto [ll, d_theta] = tied_gradient(q, i, g);
      if (!grad.empty()) grad = {-d_theta};
      return -ll;
    };
    minimise_local(data, f, x, {std::log(lower)}, {std::log(upper) - 1e-6});
    p.theta[static_cast<std::size_t>(i)] = std::exp(x[0]);
    tie_lower(p, ratios, i);
  }
  // (9): all thetas and both sigmas, theta kept in Theta by theta_1 = e^{u_1}, theta_{i+1} = theta_i +
  // e^{u_{i+1}} (constraint (5) by construction), sigmas by their logs; analytic gradient, L-BFGS.
  {
    const int n = m + 2;
    std::vector<double> x(static_cast<std::size_t>(n));
    x[0] = std::log(p.theta[0]);
    for (int i = 1; i < m; ++i)
      x[i] = std::log(std::max(p.theta[i] - p.theta[i - 1], 1e-9));
    x[m] = std::log(p.sigma_s);
    x[m + 1] = std::log(p.sigma_v);
    auto f = [&](const std::vector<double>& y, std::vector<double>& grad) {
      MixtureParams q = p;
      q.theta[0] = std::exp(y[0]);
      for (int i = 1; i < m; ++i)
        q.theta[i] = q.theta[i - 1] + std::exp(y[i]);
      q.sigma_s = std::exp(y[m]);
      q.sigma_v = std::exp(y[m + 1]);
      Eigen::VectorXd g;
      const double ll = log_likelihood_gradient(data, q, layout, g);
      if (!grad.empty()) {
        // d/du_j of theta_i (i >= j) is e^{u_j}: accumulate from the top gear down.
        double tail = 0.0;
        for (int j = m - 1; j >= 0; --j) {
          tail += g[j];
          grad[static_cast<std::size_t>(j)] = -tail * std::exp(y[j]);
        }
        grad[static_cast<std::size_t>(m)] = -g[m] * q.sigma_s;
        grad[static_cast<std::size_t>(m + 1)] = -g[m + 1] * q.sigma_v;
      }
      return -ll;
    };
    const std::vector<double> unbounded(static_cast<std::size_t>(n), HUGE_VAL);
    const std::vector<double> below(unbounded.size(), -HUGE_VAL);
    minimise_local(data, f, x, below, unbounded);
    p.theta[0] = std::exp(x[0]);
    for (int i = 1; i < m; ++i)
      p.theta[i] = p.theta[i - 1] + std::exp(x[i]);
    p.sigma_s = std::exp(x[m]);
    p.sigma_v = std::exp(x[m + 1]);
  }
  return finish_model(data, p, "paper", GradientLayout{m, false, false});
}

}  // namespace gearpulse::detail
