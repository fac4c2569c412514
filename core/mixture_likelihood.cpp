#include "core/mixture_likelihood.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "core/estimator.hpp"

namespace gearpulse::detail {
namespace {

constexpr double kLogTwoPi = 1.8378770664093453;
constexpr double kTiny = 1e-300;

// Runs fn(begin, end, slot) over the data's [0, n) in one slice, or in two (one per half, on the data's
// runner) from kParallelSamples on, and returns the two slot results.
template <typename Result, typename Fn>
std::pair<Result, Result> split_two(const MixtureData& data, Fn&& fn) {
  throw_if_stopped(data);
  const std::size_t n = data.size();
  Result a{};
  Result b{};
  if (n < kParallelSamples) {
    fn(std::size_t{0}, n, a);
    return {std::move(a), std::move(b)};
  }
  const std::size_t mid = n / 2;
  const auto half = [&](std::size_t i) {
    if (i == 0)
      fn(std::size_t{0}, mid, a);
    else
      fn(mid, n, b);
  };
  if (data.parallel != nullptr) {
    data.parallel->run(2, half);
  } else {
    half(0);
    half(1);
  }
  return {std::move(a), std::move(b)};
}

// Per-component constant parts of the log density.
struct Precomputed {
  std::vector<double> log_alpha;
  std::vector<double> inv_var;
  std::vector<double> log_norm;  // -0.5 log(2 pi tau^2)
  double log_stand = -INFINITY;
  double stand_inv_var = 0.0;
  double log_clutch = -INFINITY;
  std::vector<double> log_g;
  double g_scale = 0.0;
};

Precomputed precompute(const MixtureParams& p) {
  Precomputed c;
  const int m = p.gears();
  const double a = p.sigma_s * p.sigma_s;
  const double b = p.sigma_v * p.sigma_v;
  for (int i = 0; i < m; ++i) {
    const double var = p.theta[i] * p.theta[i] * a + b;
    c.log_alpha.push_back(std::log(std::max(p.alpha[i], kTiny)));
    c.inv_var.push_back(1.0 / var);
    c.log_norm.push_back(-0.5 * (kLogTwoPi + std::log(var)));
  }
  if (p.beta_stand > 0.0) {
    // Half-normal on v >= 0: 2 N(v; 0, stand_sigma^2).
    c.log_stand = std::log(p.beta_stand) + std::log(2.0) - 0.5 * (kLogTwoPi + 2.0 * std::log(p.stand_sigma));
    c.stand_inv_var = 1.0 / (p.stand_sigma * p.stand_sigma);
  }
  if (p.beta_clutch > 0.0 && !p.g_density.empty()) {
    c.log_clutch = std::log(p.beta_clutch);
    for (double d : p.g_density)
      c.log_g.push_back(std::log(std::max(d, kTiny)));
    c.g_scale = static_cast<double>(p.g_density.size()) / (p.g_hi - p.g_lo);
  }
  return c;
}

inline int g_bin(const MixtureParams& p, const Precomputed& c, double v) {
  const double x = (v - p.g_lo) * c.g_scale;
  if (!(x >= 0.0)) return -1;
  const auto bin = static_cast<std::size_t>(x);
  if (bin >= p.g_density.size())
    return x <= static_cast<double>(p.g_density.size()) + 1e-9 ? static_cast<int>(p.g_density.size()) - 1
                                                               : -1;
  return static_cast<int>(bin);
}

// Log terms of every component for one sample; returns log p and fills `terms` (gears, stand, clutch).
inline double sample_terms(const MixtureParams& p, const Precomputed& c, double v, double s, double* terms,
                           int& bin) {
  const int m = p.gears();
  double best = -INFINITY;
  for (int i = 0; i < m; ++i) {
    const double e = v - p.theta[i] * s;
    terms[i] = c.log_alpha[i] + c.log_norm[i] - 0.5 * e * e * c.inv_var[i];
    best = std::max(best, terms[i]);
  }
  terms[m] = c.log_stand > -INFINITY && v >= 0.0 ? c.log_stand - 0.5 * v * v * c.stand_inv_var : -INFINITY;
  best = std::max(best, terms[m]);
  bin = c.log_clutch > -INFINITY ? g_bin(p, c, v) : -1;
  terms[m + 1] = bin >= 0 ? c.log_clutch + c.log_g[static_cast<std::size_t>(bin)] : -INFINITY;
  best = std::max(best, terms[m + 1]);
  if (best == -INFINITY) return std::log(kTiny);
  double sum = 0.0;
  for (int i = 0; i < m + 2; ++i) {
    terms[i] = std::exp(terms[i] - best);
    sum += terms[i];
  }
  for (int i = 0; i < m + 2; ++i)
    terms[i] /= sum;  // now responsibilities
  return best + std::log(sum);
}

}  // namespace

void throw_if_stopped(const MixtureData& data) {
  if (data.stop.stop_requested()) throw FitCancelled();
}

double log_likelihood(const MixtureData& data, const MixtureParams& p) {
  const Precomputed c = precompute(p);
  auto [a, b] = split_two<double>(data, [&](std::size_t begin, std::size_t end, double& out) {
    std::vector<double> terms(static_cast<std::size_t>(p.gears()) + 2);
    int bin = 0;
    double sum = 0.0;
    for (std::size_t k = begin; k < end; ++k)
      sum += sample_terms(p, c, data.v[k], data.s[k], terms.data(), bin);
    out = sum;
  });
  return a + b;
}

double log_likelihood_gradient(const MixtureData& data, const MixtureParams& p, const GradientLayout& layout,
                               Eigen::VectorXd& gradient) {
  const Precomputed c = precompute(p);
  const int m = p.gears();
  const int n_par = layout.size();
  const double a = p.sigma_s * p.sigma_s;
  struct Acc {
    double ll = 0.0;
    Eigen::VectorXd g;
  };
  auto [x, y] = split_two<Acc>(data, [&](std::size_t begin, std::size_t end, Acc& out) {
    out.g = Eigen::VectorXd::Zero(n_par);
    std::vector<double> r(static_cast<std::size_t>(m) + 2);
    int bin = 0;
    double ll = 0.0;
    for (std::size_t k = begin; k < end; ++k) {
      const double v = data.v[k];
      const double s = data.s[k];
      ll += sample_terms(p, c, v, s, r.data(), bin);
      double d_a = 0.0;
      double d_b = 0.0;
      for (int i = 0; i < m; ++i) {
        if (r[i] < 1e-12) continue;
        const double e = v - p.theta[i] * s;
        const double iv = c.inv_var[i];
        const double common = -0.5 * iv + 0.5 * e * e * iv * iv;  // d log phi / d tau^2
        out.g[i] += r[i] * (e * s * iv + common * 2.0 * p.theta[i] * a);
        d_a += r[i] * common * p.theta[i] * p.theta[i];
        d_b += r[i] * common;
      }
      out.g[m] += d_a * 2.0 * p.sigma_s;
      out.g[m + 1] += d_b * 2.0 * p.sigma_v;
      if (layout.with_weights) {
        // d log p / d eta_j = r_j - alpha_j (softmax with beta_clutch as reference).
        for (int i = 0; i < m; ++i)
          out.g[m + 2 + i] += r[i] - p.alpha[i];
        if (layout.with_stand) out.g[2 * m + 2] += r[m] - p.beta_stand;
      }
    }
    out.ll = ll;
  });
  gradient = x.g;
  if (y.g.size() == gradient.size()) gradient += y.g;
  return x.ll + y.ll;
}

Eigen::VectorXd to_vector(const MixtureParams& p, const GradientLayout& layout) {
  Eigen::VectorXd x(layout.size());
  const int m = p.gears();
  for (int i = 0; i < m; ++i)
    x[i] = p.theta[i];
  x[m] = p.sigma_s;
  x[m + 1] = p.sigma_v;
  if (layout.with_weights) {
    const double ref = std::log(std::max(p.beta_clutch, kTiny));
    for (int i = 0; i < m; ++i)
      x[m + 2 + i] = std::log(std::max(p.alpha[i], kTiny)) - ref;
    if (layout.with_stand) x[2 * m + 2] = std::log(std::max(p.beta_stand, kTiny)) - ref;
  }
  return x;
}

MixtureParams with_vector(const MixtureParams& p, const GradientLayout& layout, const Eigen::VectorXd& x) {
  MixtureParams q = p;
  const int m = p.gears();
  for (int i = 0; i < m; ++i)
    q.theta[i] = x[i];
  q.sigma_s = std::abs(x[m]);
  q.sigma_v = std::abs(x[m + 1]);
  if (layout.with_weights) {
    double sum = 1.0;  // the reference (clutch) has eta = 0
    for (int i = 0; i < m; ++i)
      sum += std::exp(x[m + 2 + i]);
    if (layout.with_stand) sum += std::exp(x[2 * m + 2]);
    for (int i = 0; i < m; ++i)
      q.alpha[i] = std::exp(x[m + 2 + i]) / sum;
    if (layout.with_stand) q.beta_stand = std::exp(x[2 * m + 2]) / sum;
    q.beta_clutch = 1.0 / sum;
  }
  return q;
}

Eigen::MatrixXd observed_information_numeric(const MixtureData& data, const MixtureParams& p,
                                             const GradientLayout& layout) {
  const int n_par = layout.size();
  const Eigen::VectorXd x0 = to_vector(p, layout);
  Eigen::MatrixXd h(n_par, n_par);
  Eigen::VectorXd gp;
  Eigen::VectorXd gm;
  for (int j = 0; j < n_par; ++j) {
    const double step = 1e-5 * std::max(std::abs(x0[j]), 1e-3);
    Eigen::VectorXd xp = x0;
    Eigen::VectorXd xm = x0;
    xp[j] += step;
    xm[j] -= step;
    (void)log_likelihood_gradient(data, with_vector(p, layout, xp), layout, gp);
    (void)log_likelihood_gradient(data, with_vector(p, layout, xm), layout, gm);
    h.col(j) = (gp - gm) / (2.0 * step);
  }
  return -0.5 * (h + h.transpose());
}

// Analytic Hessian in one pass. For log p = log sum_j exp(l_j), with l_j = log alpha_j + log phi_j,
//   d2 log p = sum_j r_j (d2 l_j + dl_j dl_j^T) - dlogp dlogp^T.
// Each gear's log phi depends on (theta_j, sigma_s, sigma_v) only; log alpha_j on the logits eta, with
// d log alpha_j / d eta = e_j - alpha (e_j = 0 for the reference clutch component) and a constant
// second derivative -(diag(alpha) - alpha alpha^T) that sums to itself over r.
Eigen::MatrixXd observed_information(const MixtureData& data, const MixtureParams& p,
                                     const GradientLayout& layout) {
  const Precomputed c = precompute(p);
  const int m = p.gears();
  const int n_par = layout.size();
  const int eta0 = m + 2;
  const int n_eta = layout.with_weights ? n_par - eta0 : 0;
  const double a = p.sigma_s * p.sigma_s;
  const double ss = p.sigma_s;
  const double sv = p.sigma_v;
  Eigen::VectorXd alpha_eta(n_eta);
  for (int i = 0; i < n_eta; ++i)
    alpha_eta[i] = i < m ? p.alpha[i] : p.beta_stand;
  auto [x, y] =
      split_two<Eigen::MatrixXd>(data, [&](std::size_t begin, std::size_t end, Eigen::MatrixXd& out) {
        out = Eigen::MatrixXd::Zero(n_par, n_par);
        std::vector<double> r(static_cast<std::size_t>(m) + 2);
        Eigen::VectorXd gbar(n_par);
        Eigen::VectorXd gsum = Eigen::VectorXd::Zero(n_par);
        int bin = 0;
        for (std::size_t k = begin; k < end; ++k) {
          const double v = data.v[k];
          const double s = data.s[k];
          (void)sample_terms(p, c, v, s, r.data(), bin);
          gbar.setZero();
          for (int j = 0; j < m; ++j) {
            const double rj = r[j];
            if (rj < 1e-14) continue;
            const double th = p.theta[j];
            const double q = 1.0 / c.inv_var[j];
            const double e = v - th * s;
            const double cq = -0.5 / q + 0.5 * e * e / (q * q);      // d logphi / dq
            const double cqq = 0.5 / (q * q) - e * e / (q * q * q);  // d cq / dq
            const double cqt = -e * s / (q * q);                     // d cq / dtheta at fixed q
            const double qt = 2.0 * th * a;                          // dq / dtheta
            // First derivatives in (theta, a = sigma_s^2, b = sigma_v^2).
            const double d_t = e * s / q + cq * qt;
            const double d_a = cq * th * th;
            const double d_b = cq;
            const double dcq_t = cqt + cqq * qt;  // total d cq / dtheta
            const double h_tt = -s * s / q - e * s / (q * q) * qt + 2.0 * a * cq + qt * dcq_t;
            const double h_ta = 2.0 * th * cq + th * th * dcq_t;
            const double h_tb = dcq_t;
            const double h_aa = th * th * th * th * cqq;
            const double h_ab = th * th * cqq;
            const double h_bb = cqq;
            // To (theta, sigma_s, sigma_v).
            const double g_t = d_t;
            const double g_s = 2.0 * ss * d_a;
            const double g_v = 2.0 * sv * d_b;
            const double hh_tt = h_tt;
            const double hh_ts = 2.0 * ss * h_ta;
            const double hh_tv = 2.0 * sv * h_tb;
            const double hh_ss = 4.0 * ss * ss * h_aa + 2.0 * d_a;
            const double hh_sv = 4.0 * ss * sv * h_ab;
            const double hh_vv = 4.0 * sv * sv * h_bb + 2.0 * d_b;
            const int idx[3] = {j, m, m + 1};
            const double g3[3] = {g_t, g_s, g_v};
            const double h3[3][3] = {{hh_tt, hh_ts, hh_tv}, {hh_ts, hh_ss, hh_sv}, {hh_tv, hh_sv, hh_vv}};
            for (int u = 0; u < 3; ++u) {
              gbar[idx[u]] += rj * g3[u];
              for (int w = 0; w < 3; ++w)
                out(idx[u], idx[w]) += rj * (h3[u][w] + g3[u] * g3[w]);
            }
            if (n_eta > 0) {
              // Cross terms r_j (a_j e_j^T + e_j a_j^T); the -alpha parts are covered below via gbar.
              for (int u = 0; u < 3; ++u) {
                out(idx[u], eta0 + j) += rj * g3[u];
                out(eta0 + j, idx[u]) += rj * g3[u];
              }
            }
          }
          if (n_eta > 0) {
            for (int i = 0; i < n_eta; ++i) {
              const double ri = i < m ? r[i] : r[m];
              out(eta0 + i, eta0 + i) += ri;
              gbar[eta0 + i] = ri - alpha_eta[i];
            }
            gsum += gbar;
          }
          out.noalias() -= gbar * gbar.transpose();
        }
        if (n_eta > 0) {
          // sum_j r_j dl_j dl_j^T with dl_j = a_j + e_j - alpha (eta part) expands to
          // sum_j r_j (a_j + e_j)(a_j + e_j)^T - alpha G^T - G alpha^T + alpha alpha^T, where
          // G = sum_j r_j (a_j + e_j) = gbar + alpha; log alpha adds -(diag(alpha) - alpha alpha^T). The
          // terms linear in alpha are applied once for all samples of the slice.
          const auto count = static_cast<double>(end - begin);
          Eigen::VectorXd g_total = gsum;
          g_total.segment(eta0, n_eta) += count * alpha_eta;
          out.middleCols(eta0, n_eta) -= g_total * alpha_eta.transpose();
          out.middleRows(eta0, n_eta) -= alpha_eta * g_total.transpose();
          out.block(eta0, eta0, n_eta, n_eta) += 2.0 * count * alpha_eta * alpha_eta.transpose();
          out.block(eta0, eta0, n_eta, n_eta) -= count * Eigen::MatrixXd(alpha_eta.asDiagonal());
        }
      });
  Eigen::MatrixXd h = x;
  if (y.size() == h.size()) h += y;
  return -0.5 * (h + h.transpose());
}

void EStepStats::reset(int gears, std::size_t bins) {
  const auto m = static_cast<std::size_t>(gears);
  log_likelihood = 0.0;
  r.assign(m, 0.0);
  rvs.assign(m, 0.0);
  rss.assign(m, 0.0);
  rvv.assign(m, 0.0);
  r_stand = r_stand_vv = r_clutch = 0.0;
  r_clutch_bins.assign(bins, 0.0);
}

void EStepStats::add(const EStepStats& other) {
  log_likelihood += other.log_likelihood;
  for (std::size_t i = 0; i < r.size() && i < other.r.size(); ++i) {
    r[i] += other.r[i];
    rvs[i] += other.rvs[i];
    rss[i] += other.rss[i];
    rvv[i] += other.rvv[i];
  }
  r_stand += other.r_stand;
  r_stand_vv += other.r_stand_vv;
  r_clutch += other.r_clutch;
  for (std::size_t i = 0; i < r_clutch_bins.size() && i < other.r_clutch_bins.size(); ++i)
    r_clutch_bins[i] += other.r_clutch_bins[i];
}

EStepStats e_step(const MixtureData& data, const MixtureParams& p) {
  const Precomputed c = precompute(p);
  const int m = p.gears();
  auto [x, y] = split_two<EStepStats>(data, [&](std::size_t begin, std::size_t end, EStepStats& out) {
    out.reset(m, p.g_density.size());
    std::vector<double> r(static_cast<std::size_t>(m) + 2);
    int bin = 0;
    for (std::size_t k = begin; k < end; ++k) {
      const double v = data.v[k];
      const double s = data.s[k];
      out.log_likelihood += sample_terms(p, c, v, s, r.data(), bin);
      for (int i = 0; i < m; ++i) {
        out.r[i] += r[i];
        out.rvs[i] += r[i] * v * s;
        out.rss[i] += r[i] * s * s;
        out.rvv[i] += r[i] * v * v;
      }
      out.r_stand += r[m];
      out.r_stand_vv += r[m] * v * v;
      out.r_clutch += r[m + 1];
      if (bin >= 0) out.r_clutch_bins[static_cast<std::size_t>(bin)] += r[m + 1];
    }
  });
  if (!y.r.empty()) x.add(y);
  return x;
}

namespace {

// Minimises F(a, b) = sum_i R_i log(theta_i^2 a + b) + S_i / (theta_i^2 a + b) over a = sigma_s^2,
// b = sigma_v^2 >= 0 (the sigma part of the expected negative log-likelihood). Written as a = w u / t,
// b = w (1 - u) with t the responsibility-weighted mean theta^2, the scale w has a closed-form minimiser
// for each share u in [0, 1]; F is then searched over u on a grid and refined by golden section. A local
// search in log(a), log(b) stalls where one noise level is near zero (the gradient vanishes with it),
// which left sigma_s pinned at zero and every gear line as wide as the top gear's.
void minimise_sigmas(const std::vector<double>& theta, const std::vector<double>& r_sum,
                     const std::vector<double>& sq, double& a, double& b) {
  constexpr double kFloor = 1e-12;
  double r_total = 0.0;
  double t_mean = 0.0;
  for (std::size_t i = 0; i < theta.size(); ++i) {
    r_total += r_sum[i];
    t_mean += r_sum[i] * theta[i] * theta[i];
  }
  if (!(r_total > 0.0) || !(t_mean > 0.0)) return;
  t_mean /= r_total;
  // Profile of F over the share u: returns F and the scale w at its minimum.
  auto profile = [&](double u, double& w) {
    double weighted = 0.0;
    for (std::size_t i = 0; i < theta.size(); ++i) {
      const double c = theta[i] * theta[i] / t_mean * u + (1.0 - u);
      weighted += sq[i] / c;
    }
    w = std::max(weighted / r_total, kFloor);
    double f = 0.0;
    for (std::size_t i = 0; i < theta.size(); ++i) {
      const double var = w * (theta[i] * theta[i] / t_mean * u + (1.0 - u));
      f += r_sum[i] * std::log(var) + sq[i] / var;
    }
    return f;
  };
  constexpr int kGrid = 40;
  double w = 0.0;
  int best = 0;
  double best_f = INFINITY;
  for (int g = 0; g <= kGrid; ++g) {
    const double f = profile(static_cast<double>(g) / kGrid, w);
    if (f < best_f) {
      best_f = f;
      best = g;
    }
  }
  // Golden section on the bracket around the best grid point.
  double lo = std::max(0.0, (best - 1.0) / kGrid);
  double hi = std::min(1.0, (best + 1.0) / kGrid);
  constexpr double kGolden = 0.6180339887498949;
  double x1 = hi - kGolden * (hi - lo);
  double x2 = lo + kGolden * (hi - lo);
  double f1 = profile(x1, w);
  double f2 = profile(x2, w);
  for (int it = 0; it < 40; ++it) {
    if (f1 < f2) {
      hi = x2;
      x2 = x1;
      f2 = f1;
      x1 = hi - kGolden * (hi - lo);
      f1 = profile(x1, w);
    } else {
      lo = x1;
      x1 = x2;
      f1 = f2;
      x2 = lo + kGolden * (hi - lo);
      f2 = profile(x2, w);
    }
  }
  double u = 0.5 * (lo + hi);
  if (profile(u, w) > best_f) u = static_cast<double>(best) / kGrid;
  (void)profile(u, w);
  a = std::max(w * u / t_mean, kFloor);
  b = std::max(w * (1.0 - u), kFloor);
}

}  // namespace

void m_step(const EStepStats& st, MixtureParams& p, bool fixed_weights, bool fixed_g) {
  const int m = p.gears();
  double total = st.r_clutch + st.r_stand;
  for (int i = 0; i < m; ++i)
    total += st.r[i];
  if (!(total > 0.0)) return;
  if (!fixed_weights) {
    for (int i = 0; i < m; ++i)
      p.alpha[i] = std::max(st.r[i] / total, 1e-9);
    if (p.beta_stand > 0.0) p.beta_stand = std::max(st.r_stand / total, 1e-9);
    if (p.beta_clutch > 0.0) p.beta_clutch = std::max(st.r_clutch / total, 1e-9);
  }
  if (p.beta_stand > 0.0 && st.r_stand > 1e-9) {
    p.stand_sigma = std::max(std::sqrt(st.r_stand_vv / st.r_stand), 1e-3);
  }
  if (!fixed_g && st.r_clutch > 1e-9 && !p.g_density.empty()) {
    const double width = (p.g_hi - p.g_lo) / static_cast<double>(p.g_density.size());
    // A light floor keeps g a broad density: a bin never drops to zero and captures a gear line.
    const double floor = 0.02 / (p.g_hi - p.g_lo);
    double norm = 0.0;
    for (std::size_t b = 0; b < p.g_density.size(); ++b) {
      p.g_density[b] = st.r_clutch_bins[b] / (st.r_clutch * width) + floor;
      norm += p.g_density[b] * width;
    }
    for (double& d : p.g_density)
      d /= norm;
  }
  // Thetas by weighted least squares with each component's variance held (exact for fixed tau_i).
  std::vector<double> sq(static_cast<std::size_t>(m));
  for (int i = 0; i < m; ++i) {
    if (st.rss[i] > 0.0 && st.r[i] > 1e-6) p.theta[i] = st.rvs[i] / st.rss[i];
    sq[i] = std::max(st.rvv[i] - 2.0 * p.theta[i] * st.rvs[i] + p.theta[i] * p.theta[i] * st.rss[i], 0.0);
  }
  double a = p.sigma_s * p.sigma_s;
  double b = p.sigma_v * p.sigma_v;
  minimise_sigmas(p.theta, st.r, sq, a, b);
  p.sigma_s = std::sqrt(a);
  p.sigma_v = std::sqrt(b);
}

}  // namespace gearpulse::detail
