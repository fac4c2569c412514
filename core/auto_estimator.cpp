// Auto mode, no priors: candidate gear scales from the modes of the density of log(v/s), EM fits of the
// generalised mixture for every gear count, the count chosen by BIC among ladders that pass physical
// checks, then a polish on the full data and standard errors from the observed information.
#include <algorithm>
#include <cmath>
#include <numeric>

#include "core/estimator_internal.hpp"

namespace gearpulse::detail {
namespace {

constexpr int kMaxGears = 8;
constexpr std::size_t kWorkingSamples = 60000;  // model selection runs on a subsample of this size
constexpr std::size_t kClutchBins = 24;
constexpr double kMovingSpeed = 1.0;  // m/s: only these samples seed the gear scales

struct Peak {
  double log_ratio = 0.0;
  double height = 0.0;
};

// Local maxima of a Gaussian-smoothed histogram of log(v/s), highest first.
std::vector<Peak> density_modes(const std::vector<double>& r, double bandwidth) {
  std::vector<double> sorted = r;
  std::sort(sorted.begin(), sorted.end());
  const double lo = sorted[sorted.size() / 200] - 3 * bandwidth;
  const double hi = sorted[sorted.size() - 1 - sorted.size() / 200] + 3 * bandwidth;
  const double bin = bandwidth / 4.0;
  const auto n = static_cast<std::size_t>(std::ceil((hi - lo) / bin)) + 1;
  std::vector<double> hist(n, 0.0);
  for (double x : r) {
    if (x < lo || x > hi) continue;
    hist[std::min(n - 1, static_cast<std::size_t>((x - lo) / bin))] += 1.0;
  }
  const int half = 12;  // kernel support: 3 bandwidths
  std::vector<double> kernel(2 * half + 1);
  for (int j = -half; j <= half; ++j)
    kernel[static_cast<std::size_t>(j + half)] = std::exp(-0.5 * (j / 4.0) * (j / 4.0));
  std::vector<double> smooth(n, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    double acc = 0.0;
    for (int j = -half; j <= half; ++j) {
      const auto idx = static_cast<std::ptrdiff_t>(i) + j;
      if (idx < 0 || idx >= static_cast<std::ptrdiff_t>(n)) continue;
      acc += hist[static_cast<std::size_t>(idx)] * kernel[static_cast<std::size_t>(j + half)];
    }
    smooth[i] = acc;
  }
  std::vector<Peak> peaks;
  for (std::size_t i = 1; i + 1 < n; ++i) {
    if (smooth[i] > smooth[i - 1] && smooth[i] >= smooth[i + 1] && smooth[i] > 0.0)
      peaks.push_back({lo + (static_cast<double>(i) + 0.5) * bin, smooth[i]});
  }
  std::sort(peaks.begin(), peaks.end(), [](const Peak& a, const Peak& b) { return a.height > b.height; });
  return peaks;
}

MixtureData subsample(const MixtureData& all, std::size_t target) {
  if (all.size() <= target) return all;
  MixtureData out;
  const double stride = static_cast<double>(all.size()) / static_cast<double>(target);
  for (std::size_t i = 0; i < target; ++i) {
    const auto k = static_cast<std::size_t>(static_cast<double>(i) * stride);
    out.v.push_back(all.v[k]);
    out.s.push_back(all.s[k]);
  }
  return out;
}

double run_em(const MixtureData& data, MixtureParams& p, int max_iter, double tol) {
  double previous = -INFINITY;
  double ll = -INFINITY;
  for (int it = 0; it < max_iter; ++it) {
    const EStepStats st = e_step(data, p);
    ll = st.log_likelihood;
    m_step(st, p, false, false);
    // Keep constraint (5): a component that crossed its neighbour is put back in order.
    std::vector<std::size_t> order(p.theta.size());
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(),
              [&](std::size_t a, std::size_t b) { return p.theta[a] < p.theta[b]; });
    std::vector<double> th;
    std::vector<double> al;
    for (std::size_t i : order) {
      th.push_back(p.theta[i]);
      al.push_back(p.alpha[i]);
    }
    p.theta = th;
    p.alpha = al;
    if (std::abs(ll - previous) < tol * static_cast<double>(data.size())) break;
    previous = ll;
  }
  return log_likelihood(data, p);
}

MixtureParams initial_params(const MixtureData& data, const std::vector<double>& log_ratios, double vmax) {
  MixtureParams p;
  for (double r : log_ratios)
    p.theta.push_back(std::exp(r));
  std::sort(p.theta.begin(), p.theta.end());
  std::size_t standing = 0;
  for (double v : data.v)
    standing += v < 0.5 ? 1 : 0;
  const double stand_share =
      std::clamp(static_cast<double>(standing) / static_cast<double>(data.size()), 0.02, 0.9);
  p.beta_stand = stand_share;
  p.stand_sigma = 0.2;
  p.beta_clutch = 0.1;
  const double gear_share = std::max(1.0 - p.beta_stand - p.beta_clutch, 0.05);
  p.alpha.assign(p.theta.size(), gear_share / static_cast<double>(p.theta.size()));
  const double total = gear_share + p.beta_stand + p.beta_clutch;
  for (double& a : p.alpha)
    a /= total;
  p.beta_stand /= total;
  p.beta_clutch /= total;
  p.g_lo = 0.0;
  p.g_hi = vmax * 1.0001 + 1e-6;
  p.g_density.assign(kClutchBins, 1.0 / (p.g_hi - p.g_lo));
  std::vector<double> s_sorted = data.s;
  std::nth_element(s_sorted.begin(), s_sorted.begin() + static_cast<std::ptrdiff_t>(s_sorted.size() / 2),
                   s_sorted.end());
  p.sigma_s = 0.01 * s_sorted[s_sorted.size() / 2];
  p.sigma_v = 0.01 * vmax + 0.05;
  return p;
}

struct Candidate {
  MixtureParams params;
  double log_likelihood = -INFINITY;
  double bic = INFINITY;
  bool valid = false;
  std::string reason;
};

// Physical checks of a fitted ladder (beyond what the likelihood sees).
bool plausible_ladder(const MixtureData& data, const MixtureParams& p, std::string& reason) {
  const int m = p.gears();
  if (m < 2) {
    reason = "only one gear-like cluster (one gear used, or an automatic/CVT)";
    return false;
  }
  double gear_total = 0.0;
  for (double a : p.alpha)
    gear_total += a;
  for (int i = 0; i < m; ++i) {
    const double share = p.alpha[i] / gear_total;
    if (share < 0.01 || p.alpha[i] * static_cast<double>(data.size()) < 10.0) {
      reason = "a gear cluster carries too few samples";
      return false;
    }
  }
  for (int i = 0; i + 1 < m; ++i) {
    const double step = p.theta[i + 1] / p.theta[i];
    if (step < 1.06 || step > 2.6) {
      reason = "implausible spacing between gear clusters";
      return false;
    }
  }
  return true;
}

}  // namespace

GearModel fit_auto(const MixtureData& all, int gears) {
  GearModel model;
  model.method = "auto";
  model.samples = all.size();
  std::vector<double> log_ratios;
  double vmax = 0.0;
  for (std::size_t k = 0; k < all.size(); ++k) {
    vmax = std::max(vmax, all.v[k]);
    if (all.v[k] > kMovingSpeed) log_ratios.push_back(std::log(all.v[k] / all.s[k]));
  }
  if (log_ratios.size() < 30) {
    model.reason =
        all.size() == 0 ? "no samples with both speed and frequency" : "too few samples while moving";
    return model;
  }
  const MixtureData work = subsample(all, kWorkingSamples);
  std::vector<std::vector<Peak>> peak_sets = {
      density_modes(log_ratios, 0.006), density_modes(log_ratios, 0.015), density_modes(log_ratios, 0.03)};
  const int m_lo = gears > 0 ? gears : 1;
  const int m_hi = gears > 0 ? gears : kMaxGears;
  Candidate best;
  Candidate best_any;
  for (int m = m_lo; m <= m_hi; ++m) {
    for (const auto& peaks : peak_sets) {
      if (static_cast<int>(peaks.size()) < m) continue;
      std::vector<double> init;
      for (const Peak& pk : peaks) {
        bool close = false;
        for (double x : init)
          close = close || std::abs(x - pk.log_ratio) < 0.04;
        if (!close) init.push_back(pk.log_ratio);
        if (static_cast<int>(init.size()) == m) break;
      }
      if (static_cast<int>(init.size()) < m) continue;
      Candidate c;
      c.params = initial_params(work, init, vmax);
      c.log_likelihood = run_em(work, c.params, 300, 1e-7);
      const double n_params = 2.0 * m + 2.0 + 2.0 + 1.0 + (kClutchBins - 1);
      c.bic = -2.0 * c.log_likelihood + n_params * std::log(static_cast<double>(work.size()));
      c.valid = plausible_ladder(work, c.params, c.reason);
      if (c.bic < best_any.bic) best_any = c;
      if (c.valid && c.bic < best.bic) best = c;
    }
  }
  if (!best.valid || (gears == 0 && best_any.params.gears() < 2)) {
    model.reason = best_any.reason.empty() ? "no discrete gear ladder in the data" : best_any.reason;
    return model;
  }
  MixtureParams p = best.params;
  if (work.size() < all.size()) (void)run_em(all, p, 30, 1e-9);
  return finish_model(all, p, "auto", GradientLayout{p.gears(), true, p.beta_stand > 0.0});
}

}  // namespace gearpulse::detail
