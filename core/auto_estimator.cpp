// Auto mode, no priors: candidate gear scales from the modes of the density of log(v/s), EM fits of the
// generalised mixture for every gear count, the count chosen by BIC among ladders that pass physical
// checks, then a polish on the full data and standard errors from the observed information.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <optional>
#include <span>

#include "core/estimator.hpp"
#include "core/estimator_internal.hpp"

namespace gearpulse::detail {
namespace {

constexpr int kMaxCandidates = 10;              // gear scales tried at first (more than any gearbox has)
constexpr std::size_t kWorkingSamples = 16000;  // model selection runs on a subsample of this size
constexpr int kEmIterations = 120;
constexpr int kFullDataIterations = 4;
constexpr std::size_t kClutchBins = 24;
constexpr std::size_t kMinMovingSamples = 30;  // moving samples a fit needs at least

struct Peak {
  double log_ratio = 0.0;
  double height = 0.0;
};

// Local maxima of a Gaussian-smoothed histogram of log(v/s), highest first.
std::vector<Peak> density_modes(const std::vector<double>& r, double bandwidth) {
  std::vector<double> sorted = r;
  std::sort(sorted.begin(), sorted.end());
  // The whole range: the lowest gear is often the rarest (a highway drive launches a few times), and
  // trimming even half a percent of the smallest ratios removes it. Only absurd ratios (a factor of 1e5
  // from the median, nothing a gearbox spans) are left out to bound the histogram.
  const double median = sorted[sorted.size() / 2];
  const double lo = std::max(sorted.front(), median - 12.0) - 3 * bandwidth;
  const double hi = std::min(sorted.back(), median + 12.0) + 3 * bandwidth;
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

// One sample from each of `target` equal strata of the data, spread over its time as a stride would be,
// at an offset within the stratum that steps by the golden ratio's fraction from one stratum to the next.
// A plain stride aliases with any period of the data that shares its factors (every 150th sample of a
// 2400-sample drive repeated 1000 times is one of the same 16 samples of the drive); the golden-ratio
// offsets cover every phase of any period evenly.
MixtureData subsample(const MixtureData& all, std::size_t target) {
  if (all.size() <= target) return all;
  MixtureData out;
  out.parallel = all.parallel;
  out.stop = all.stop;
  const double stride = static_cast<double>(all.size()) / static_cast<double>(target);
  const double golden = 0.5 * (std::sqrt(5.0) - 1.0);
  for (std::size_t i = 0; i < target; ++i) {
    const double offset = std::fmod(static_cast<double>(i) * golden, 1.0);
    const auto k =
        std::min(all.size() - 1, static_cast<std::size_t>((static_cast<double>(i) + offset) * stride));
    out.v.push_back(all.v[k]);
    out.s.push_back(all.s[k]);
  }
  return out;
}

// Generalised EM until the log-likelihood gain per sample falls below tol. Returns the log-likelihood of
// the final parameters if final_value, else that of the last E-step (saves a pass on large data).
double run_em(const MixtureData& data, MixtureParams& p, int max_iter, double tol, bool final_value = true) {
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
  return final_value ? log_likelihood(data, p) : ll;
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
};

// What the physics of a gearbox asks of a fitted ladder, beyond the likelihood.
struct LadderCheck {
  int offender = -1;  // component to drop first, -1 if the ladder is plausible
  std::string reason;
};

class LadderJudge {
 public:
  LadderJudge(const MixtureData& work, std::size_t total_samples, std::vector<double> steady_log_ratios,
              std::vector<double> moving_log_ratios)
      : work_(work),
        total_(total_samples),
        log_ratios_(std::move(steady_log_ratios)),
        moving_(std::move(moving_log_ratios)) {
    std::sort(log_ratios_.begin(), log_ratios_.end());
    std::sort(moving_.begin(), moving_.end());
    // The idle frequency, from standstill samples, if the log has enough of them.
    constexpr std::size_t kMinIdleSamples = 20;
    if (const auto idle = estimate_idle(work, kMinIdleSamples)) idle_freq_ = idle->freq;
  }

  // Hz: the idle frequency of the standstill samples; 0 when the log has too few of them.
  double idle_freq() const { return idle_freq_; }

  LadderCheck check(const MixtureParams& p) const {
    const int m = p.gears();
    double gear_total = 0.0;
    for (double a : p.alpha)
      gear_total += a;
    // Every gear carries a real share of the driving. Five samples is the floor: a highway drive at 1 Hz
    // shows its first gear only five to ten times (a second or two per launch, a few launches), while
    // fewer than five samples on a line are as likely a coincidence of shift transients.
    int weakest = -1;
    for (int i = 0; i < m; ++i) {
      const double share = p.alpha[i] / gear_total;
      const double expected = p.alpha[i] * static_cast<double>(total_);
      if (share < 0.002 || expected < 5.0) {
        if (weakest < 0 || p.alpha[i] < p.alpha[weakest]) weakest = i;
      }
    }
    if (weakest >= 0) return {weakest, "a gear cluster carries too few samples"};
    // Two clusters alone are the weakest sign of a gearbox: a CVT holds its top ratio at speed (one heavy
    // cluster), and a bump of its continuum below it (a speed often driven at one engine speed) makes a
    // pair. A drive that shows a manual in only two gears drives both, while such a bump carries a few
    // percent of the in-gear weight at most.
    constexpr double kMinPairShare = 0.05;
    if (m == 2) {
      const int lighter = p.alpha[0] < p.alpha[1] ? 0 : 1;
      if (p.alpha[lighter] < kMinPairShare * gear_total)
        return {lighter,
                "two gear clusters, the lighter with under 5 % of the driving in gear (one heavy "
                "cluster and a bump beside it, as a CVT gives)"};
    }
    // Adjacent gears are distinct (eq. (10)) and separated by a valley of the log(v/s) density: a smear
    // (clutch slip, CVT) fitted by several narrow components has no valleys.
    for (int i = 0; i + 1 < m; ++i) {
      const double step = p.theta[i + 1] / p.theta[i];
      // Of two clusters too close or without a valley, the one with less steady support goes.
      const double w = 0.2 * std::log(step);
      const int smaller =
          steady_support(std::log(p.theta[i]), w) < steady_support(std::log(p.theta[i + 1]), w) ? i : i + 1;
      if (step < 1.06) return {smaller, "gear clusters closer than any gearbox step"};
      if (step > 2.6) return {smaller, "gear clusters further apart than any gearbox step"};
      if (!valley_between(std::log(p.theta[i]), std::log(p.theta[i + 1])))
        return {smaller, "no valley between gear clusters (a continuum, as from a CVT or clutch slip)"};
    }
    // A gear drives the engine above idle over a range of engine speeds: through it, engine speed rises
    // with road speed up to the next shift. A cluster of crawl speeds whose samples stay within half an
    // idle speed above idle (nine in ten of them), or within a narrow band, is a slipping clutch holding
    // the engine at a set speed while the car crawls (a jam) slower than first gear carries it at those
    // revs. A low gear also used at a crawl still reaches well above idle on every launch. First gear at
    // idle moves a car at 1.3-2.6 m/s (overall ratios of 12-16:1, tyres of 1.9-2 m, idle at 600-1000 rpm),
    // so under 4 m/s at 1.5 idles: a cluster whose median speed is faster is no crawl, but a gear cruised
    // at low revs, as a young drive shows a gear held at one speed while a cold engine still idles high.
    constexpr double kCrawlSpeed = 4.0;  // m/s
    if (idle_freq_ > 0.0) {
      for (int i = 0; i < m; ++i) {
        const FreqSpread f = freq_spread(p, i);
        if (f.speed_median < kCrawlSpeed && f.median < 1.5 * idle_freq_ &&
            (f.p90 < 1.5 * idle_freq_ || f.p90 < 1.12 * f.p10))
          return {i, "a cluster at idle frequency (clutch slip)"};
      }
    }
    return {};
  }

 private:
  static std::size_t count_in(const std::vector<double>& sorted, double lo, double hi) {
    return static_cast<std::size_t>(std::upper_bound(sorted.begin(), sorted.end(), hi) -
                                    std::lower_bound(sorted.begin(), sorted.end(), lo));
  }
  std::size_t count_in(double lo, double hi) const { return count_in(log_ratios_, lo, hi); }

  double steady_support(double centre, double half_width) const {
    return static_cast<double>(count_in(centre - half_width, centre + half_width));
  }

  // The steady ratios decide where they show both clusters. A gear held for less than the log's sample
  // interval (first gear at 0.5 Hz: a second or two per launch) leaves few samples that agree with a
  // neighbour; then all moving ratios decide (a cluster's own samples and the valley beside it).
  bool valley_between(double a, double b) const {
    return valley_in(log_ratios_, a, b).value_or(valley_in(moving_, a, b).value_or(false));
  }

  // Whether a valley lies between the peaks at a and b; nothing when a peak has too few samples to tell.
  static std::optional<bool> valley_in(const std::vector<double>& sorted, double a, double b) {
    const double w = (b - a) / 6.0;
    const double peak =
        static_cast<double>(std::min(count_in(sorted, a - w, a + w), count_in(sorted, b - w, b + w)));
    if (peak < 6.0) return std::nullopt;
    const double mid = 0.5 * (a + b);
    return static_cast<double>(count_in(sorted, mid - w, mid + w)) < 0.5 * peak;
  }

  struct FreqSpread {
    double p10 = 0.0;  // Hz
    double median = 0.0;
    double p90 = 0.0;
    double speed_median = 0.0;  // m/s
  };

  FreqSpread freq_spread(const MixtureParams& p, int gear) const {
    // Samples close to the gear line (within 3 of its standard deviations) stand for the component.
    std::vector<double> freqs;
    std::vector<double> speeds;
    const double var = p.theta[gear] * p.theta[gear] * p.sigma_s * p.sigma_s + p.sigma_v * p.sigma_v;
    const double limit = 3.0 * std::sqrt(var);
    for (std::size_t k = 0; k < work_.size(); ++k) {
      if (work_.v[k] > 0.3 && std::abs(work_.v[k] - p.theta[gear] * work_.s[k]) < limit) {
        freqs.push_back(work_.s[k]);
        speeds.push_back(work_.v[k]);
      }
    }
    if (freqs.empty()) return {};
    std::sort(freqs.begin(), freqs.end());
    const std::size_t n = freqs.size() - 1;
    std::nth_element(speeds.begin(), speeds.begin() + static_cast<std::ptrdiff_t>(n / 2), speeds.end());
    return {freqs[n / 10], freqs[n / 2], freqs[n - n / 10], speeds[n / 2]};
  }

  const MixtureData& work_;
  std::size_t total_;
  std::vector<double> log_ratios_;
  std::vector<double> moving_;
  double idle_freq_ = 0.0;
};

double bic_of(double log_likelihood, int gears, std::size_t n) {
  // Free parameters: theta and alpha per gear, two sigmas, standstill weight and width, clutch weight and
  // its bins; only the 2 per gear differ between candidates.
  const double n_params = 2.0 * gears + 2.0 + 2.0 + 1.0 + static_cast<double>(kClutchBins - 1);
  return -2.0 * log_likelihood + n_params * std::log(static_cast<double>(n));
}

MixtureParams without(const MixtureParams& p, int drop) {
  MixtureParams q = p;
  q.theta.erase(q.theta.begin() + drop);
  q.beta_clutch += q.alpha[static_cast<std::size_t>(drop)];
  q.alpha.erase(q.alpha.begin() + drop);
  return q;
}

// log(v/s) of the moving samples that agree with a time neighbour: a sample in gear shares its ratio with
// the sample before or after it, while shifts, clutch slip and an OBD logger's skewed polls give isolated
// ratios. The tolerance widens at low speed where a few tenths of m/s of speed error (GPS noise, integer
// km/h) move the ratio. Without usable time stamps every moving sample counts.
std::vector<double> steady_log_ratios(const MixtureData& all, bool& timed) {
  std::vector<double> out;
  timed = false;
  const std::size_t n = all.size();
  auto moving = [&](std::size_t k) { return all.v[k] > kMovingSpeed; };
  std::vector<double> gaps;
  if (all.t.size() == n) {
    for (std::size_t k = 1; k < n; ++k) {
      const double dt = all.t[k] - all.t[k - 1];
      if (dt > 0.0) gaps.push_back(dt);
    }
  }
  if (gaps.empty() || gaps.size() < n / 2) {
    for (std::size_t k = 0; k < n; ++k)
      if (moving(k)) out.push_back(std::log(all.v[k] / all.s[k]));
    return out;
  }
  timed = true;
  std::nth_element(gaps.begin(), gaps.begin() + static_cast<std::ptrdiff_t>(gaps.size() / 2), gaps.end());
  const double max_gap = 3.0 * gaps[gaps.size() / 2];
  auto agree = [&](std::size_t k, std::size_t j, double r) {
    if (!moving(j) || std::abs(all.t[j] - all.t[k]) > max_gap) return false;
    return steady_ratios_agree(r, std::log(all.v[j] / all.s[j]), all.v[k]);
  };
  for (std::size_t k = 0; k < n; ++k) {
    if (!moving(k)) continue;
    const double r = std::log(all.v[k] / all.s[k]);
    if ((k > 0 && agree(k, k - 1, r)) || (k + 1 < n && agree(k, k + 1, r))) out.push_back(r);
  }
  return out;
}

// Candidate gear scales: modes of log(v/s) at three smoothing widths, merged, highest first.
std::vector<double> candidate_scales(const std::vector<double>& log_ratios, std::size_t limit) {
  std::vector<Peak> all;
  for (double bw : {0.006, 0.015, 0.03}) {
    const auto peaks = density_modes(log_ratios, bw);
    all.insert(all.end(), peaks.begin(), peaks.end());
  }
  std::sort(all.begin(), all.end(), [](const Peak& a, const Peak& b) { return a.height > b.height; });
  std::vector<double> out;
  for (const Peak& pk : all) {
    bool close = false;
    for (double x : out)
      close = close || std::abs(x - pk.log_ratio) < 0.05;
    if (!close) out.push_back(pk.log_ratio);
    if (out.size() == limit) break;
  }
  return out;
}

// The sample at or before `target`, walking from sample k only over steps of time forward within
// max_gap (joined logs restart their clocks: a walk across one would read another log, and could cross
// all of it); nullopt where the walk meets such a step or target lies before the first sample.
std::optional<std::size_t> sample_at_or_before(const MixtureData& d, std::size_t k, double target,
                                               double max_gap) {
  const std::size_t n = d.size();
  auto step_ok = [&](std::size_t i) { return d.t[i + 1] - d.t[i] > 0.0 && d.t[i + 1] - d.t[i] <= max_gap; };
  std::size_t a = k;
  while (a + 1 < n && d.t[a + 1] <= target) {
    if (!step_ok(a)) return std::nullopt;
    ++a;
  }
  while (a > 0 && d.t[a] > target) {
    if (!step_ok(a - 1)) return std::nullopt;
    --a;
  }
  if (d.t[a] > target) return std::nullopt;
  return a;
}

// Speed read at a time offset from engine speed: v interpolated linearly to t + delta between the two
// samples around it (no change at the ends or across a gap).
double shifted_speed(const MixtureData& d, std::size_t k, double delta, double max_gap) {
  if (delta == 0.0) return d.v[k];
  const double target = d.t[k] + delta;
  const auto a = sample_at_or_before(d, k, target, max_gap);
  if (!a) return d.v[k];
  if (d.t[*a] == target) return std::max(0.0, d.v[*a]);
  const std::size_t b = *a + 1;
  if (b >= d.size()) return d.v[k];
  const double dt = d.t[b] - d.t[*a];
  if (!(dt > 0.0) || dt > max_gap) return d.v[k];  // a gap, or time restarting
  return std::max(0.0, d.v[*a] + (d.v[b] - d.v[*a]) * (target - d.t[*a]) / dt);
}

constexpr std::size_t kSearchTaps = 6;
using SearchKernel = std::array<double, kSearchTaps>;

// The lag search's reading (search_speed below) as weights on six samples at times x from the instant
// read (ascending, none at 0); nullopt when the spacing leaves more than twice a sample's noise (a step
// much shorter than its neighbours).
std::optional<SearchKernel> search_kernel(std::array<double, kSearchTaps> x) {
  const double scale = std::max(-x[0], x[kSearchTaps - 1]);
  for (double& xj : x)
    xj /= scale;
  // Lagrange weights of the cubic through the middle four, at x = 0.
  SearchKernel w{};
  for (std::size_t j = 1; j + 1 < kSearchTaps; ++j) {
    w[j] = 1.0;
    for (std::size_t i = 1; i + 1 < kSearchTaps; ++i)
      if (i != j) w[j] *= -x[i] / (x[j] - x[i]);
  }
  // The quartic contrast: x^4 made orthogonal to 1, x, x^2 and x^3 on the six points (Gram-Schmidt),
  // unit length. An even pattern: it leaves every cubic read exactly, and its amount is the same for an
  // offset and its mirror.
  std::array<SearchKernel, 5> basis{};
  for (std::size_t m = 0; m < 5; ++m) {
    for (std::size_t j = 0; j < kSearchTaps; ++j)
      basis[m][j] = m == 0 ? 1.0 : basis[m - 1][j] * x[j];  // degree m: orthogonalised, as x^m would be
    for (std::size_t i = 0; i < m; ++i) {
      double dot = 0.0;
      for (std::size_t j = 0; j < kSearchTaps; ++j)
        dot += basis[m][j] * basis[i][j];
      for (std::size_t j = 0; j < kSearchTaps; ++j)
        basis[m][j] -= dot * basis[i][j];
    }
    double norm = 0.0;
    for (std::size_t j = 0; j < kSearchTaps; ++j)
      norm += basis[m][j] * basis[m][j];
    norm = std::sqrt(norm);
    for (std::size_t j = 0; j < kSearchTaps; ++j)
      basis[m][j] /= norm;
  }
  const SearchKernel& u = basis[4];
  double wu = 0.0;
  double ww = 0.0;
  for (std::size_t j = 0; j < kSearchTaps; ++j) {
    wu += w[j] * u[j];
    ww += w[j] * w[j];
  }
  // (w + alpha u)^2 = 1, the root nearer zero. Uneven spacing can leave no root: the contrast then only
  // lowers the sum of squares as far as it goes.
  const double disc = wu * wu + 1.0 - ww;
  const double alpha = disc >= 0.0 ? -wu + (wu > 0.0 ? std::sqrt(disc) : -std::sqrt(disc)) : -wu;
  double sum_sq = 0.0;
  for (std::size_t j = 0; j < kSearchTaps; ++j) {
    w[j] += alpha * u[j];
    sum_sq += w[j] * w[j];
  }
  if (!(sum_sq <= 2.0)) return std::nullopt;
  return w;
}

// Speed at t_k + delta for the lag search, from the six samples around that time: the cubic through the
// middle four, evaluated there, plus as much of the six's quartic contrast (the pattern no cubic shows)
// as brings the weights' sum of squares back to one, the amount nearer zero. On a regular grid every
// offset then carries a whole sample's noise, as the unshifted speeds do; a speed curve's slope, bend and
// jerk are read alike at every offset; and the reading moves smoothly with the offset, mirror-alike about
// the middle between two samples. Plain linear interpolation does none of this: it halves the noise half
// a sample away, which sharpens the lines by itself (with a drive's own asymmetries that passed for a lag
// in drives without any, 0.125-0.5 s at 1 Hz), and it cuts every bend short there. NaN where the six
// samples are not there or straddle a gap or a restart of the clock.
double search_speed(const MixtureData& d, std::size_t k, double delta, double max_gap) {
  constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
  const double target = d.t[k] + delta;
  const auto at = sample_at_or_before(d, k, target, max_gap);
  if (!at || *at < 2 || *at + 3 >= d.size()) return kNone;
  const std::size_t a = *at;
  if (d.t[a] == target) return d.v[a];  // on a sample: the sample itself
  std::array<double, kSearchTaps> x{};  // times of samples a-2 .. a+3 from target
  for (std::size_t j = 0; j < kSearchTaps; ++j) {
    x[j] = d.t[a - 2 + j] - target;
    if (j > 0 && !(x[j] - x[j - 1] > 0.0 && x[j] - x[j - 1] <= max_gap)) return kNone;
  }
  const auto w = search_kernel(x);
  if (!w) return kNone;
  double v = 0.0;
  for (std::size_t j = 0; j < kSearchTaps; ++j)
    v += (*w)[j] * d.v[a - 2 + j];
  return v;
}

// Sharpness of the log(v/s) density (sum of squared bin shares, a collision probability) over the
// samples [begin, end): gear lines give narrow peaks, a misaligned speed channel smears them in
// proportion to the acceleration.
double ratio_sharpness(const MixtureData& d, std::size_t begin, std::size_t end, double delta, double gap,
                       double max_gap) {
  constexpr double kBin = 0.015;  // log units, the middle smoothing width of candidate_scales
  std::vector<double> keys;
  keys.reserve(end - begin);
  // On a regular grid of step `gap` every sample is read with the same weights: computed once here,
  // used wherever the six samples sit on that grid, the general reading elsewhere.
  const double rows = std::floor(delta / gap);
  const double frac = delta / gap - rows;
  std::optional<SearchKernel> regular;
  if (frac > 1e-9 && frac < 1.0 - 1e-9) {
    std::array<double, kSearchTaps> x{};
    for (std::size_t j = 0; j < kSearchTaps; ++j)
      x[j] = (static_cast<double>(j) - 2.0 - frac) * gap;
    regular = search_kernel(x);
  }
  const auto shift = static_cast<std::ptrdiff_t>(rows);
  auto on_grid = [&](std::size_t k) {
    const std::ptrdiff_t a = static_cast<std::ptrdiff_t>(k) + shift;
    if (a < 2 || a + 3 >= static_cast<std::ptrdiff_t>(d.size())) return false;
    for (std::ptrdiff_t j = -2; j <= 3; ++j)
      if (std::abs(d.t[static_cast<std::size_t>(a + j)] - (d.t[k] + (rows + static_cast<double>(j)) * gap)) >
          1e-6 * gap)
        return false;
    return true;
  };
  for (std::size_t k = begin; k < end; ++k) {
    double v = 0.0;
    if (regular && on_grid(k)) {
      const std::size_t a = static_cast<std::size_t>(static_cast<std::ptrdiff_t>(k) + shift);
      for (std::size_t j = 0; j < kSearchTaps; ++j)
        v += (*regular)[j] * d.v[a - 2 + j];
    } else {
      v = search_speed(d, k, delta, max_gap);
    }
    if (v > kMovingSpeed && d.s[k] > 0.0) keys.push_back(std::floor(std::log(v / d.s[k]) / kBin));
  }
  if (keys.empty()) return 0.0;
  std::sort(keys.begin(), keys.end());
  double sum = 0.0;
  std::size_t run = 1;
  for (std::size_t i = 1; i <= keys.size(); ++i) {
    if (i < keys.size() && keys[i] == keys[i - 1]) {
      ++run;
      continue;
    }
    sum += static_cast<double>(run) * static_cast<double>(run);
    run = 1;
  }
  const double n = static_cast<double>(keys.size());
  return sum / (n * n);
}

// A logger that reads speed and engine speed at different instants (OBD-II polls its PIDs in turn and
// the ECU's speed may lag; a GPS fix is reported after the audio it belongs to, by up to a second or
// so whatever the fix rate) pairs them with a time offset; at acceleration a the speed is then off by
// a * offset, in first gear as much as the step between gears. The offset, searched over +-kLagSearch
// (2 s, or one sampling interval if longer), coarse then fine, is the one that makes the gear lines
// sharpest; the speeds are moved to it. The search looks at a contiguous stretch of at most kAlignSamples
// samples (enough to see the lag, and it keeps a week-long log fast). Without time stamps nothing changes.
struct Aligned {
  MixtureData data;
  double lag = 0.0;  // s: the speed paired with engine speed at t is the one logged at t + lag
};

Aligned aligned_channels(const MixtureData& all) {
  constexpr double kLagSearch = 2.0;             // s: offsets searched, -kLagSearch to +kLagSearch
  constexpr std::size_t kAlignSamples = 200000;  // samples the search looks at
  const std::size_t n = all.size();
  if (all.t.size() != n || n < 30) return {all, 0.0};
  std::vector<double> gaps;
  for (std::size_t k = 1; k < n; ++k) {
    const double dt = all.t[k] - all.t[k - 1];
    if (dt > 0.0) gaps.push_back(dt);
  }
  if (gaps.size() < n / 2) return {all, 0.0};
  std::nth_element(gaps.begin(), gaps.begin() + static_cast<std::ptrdiff_t>(gaps.size() / 2), gaps.end());
  const double gap = gaps[gaps.size() / 2];
  const double max_gap = 3.0 * gap;
  const std::size_t begin = n > kAlignSamples ? (n - kAlignSamples) / 2 : 0;
  const std::size_t end = std::min(n, begin + kAlignSamples);
  auto sharpness = [&](double delta) {
    throw_if_stopped(all);
    return ratio_sharpness(all, begin, end, delta, gap, max_gap);
  };
  const double unshifted = sharpness(0.0);
  const double range = std::max(kLagSearch, gap);
  const double coarse = range / 8.0;
  double best_delta = 0.0;
  double best = unshifted;
  for (int step = -8; step <= 8; ++step) {
    const double delta = coarse * step;
    const double sharp = step == 0 ? unshifted : sharpness(delta);
    if (sharp > best) {
      best = sharp;
      best_delta = delta;
    }
  }
  // Refine around the optimum in finer steps, down to an eighth of a sampling interval or 1/32 s,
  // whichever is finer (at 1 Hz an eighth, 0.125 s, left first gear 2 % off in launches).
  const double finest = std::min(gap / 8.0, 1.0 / 32.0);
  for (double step = coarse / 8.0, width = coarse; width > finest + 1e-12; width = step, step /= 8.0) {
    step = std::max(step, finest);
    const double centre = best_delta;
    for (int i = -7; i <= 7; ++i) {
      const double delta = centre + i * step;
      if (i == 0 || std::abs(delta - centre) >= width || std::abs(delta) > range + 1e-9) continue;
      const double sharp = sharpness(delta);
      if (sharp > best) {
        best = sharp;
        best_delta = delta;
      }
    }
  }
  // A few percent of sharpness is what sampling noise alone gives. The search's speeds carry the same
  // noise at every offset (search_speed), and a shift must also beat its mirror: a gain the opposite
  // shift shares is no lag's.
  const double mirror = best_delta != 0.0 ? sharpness(-best_delta) : unshifted;
  if (best < 1.05 * std::max(unshifted, mirror)) return {all, 0.0};
  Aligned out{all, best_delta};
  for (std::size_t k = 0; k < n; ++k)
    out.data.v[k] = shifted_speed(all, k, best_delta, max_gap);
  return out;
}

struct Window {
  std::size_t begin = 0;
  std::size_t count = 0;
};

// The window of width 2 x kGearWindow over sorted log ratios that holds the most of them.
Window densest_window(std::span<const double> sorted) {
  Window best;
  for (std::size_t b = 0, e = 0; b < sorted.size(); ++b) {
    while (e < sorted.size() && sorted[e] <= sorted[b] + 2.0 * kGearWindow)
      ++e;
    if (e - b > best.count) best = {b, e - b};
  }
  return best;
}

// One gear, for a model still learning: the densest window of steady ratios, fitted alone, if it holds at
// least half of the steady moving pairs and fewer steady pairs than a fit needs (kMinMovingSamples) lie
// outside it (more steady driving elsewhere is a gear the ladder should show, or a continuum, as from a
// CVT below the ratio it holds at cruise), and it passes the physical checks a ladder's gears pass. An
// empty candidate otherwise.
Candidate single_cluster(const MixtureData& work, const std::vector<double>& steady, const LadderJudge& judge,
                         double vmax) {
  std::vector<double> sorted = steady;
  std::sort(sorted.begin(), sorted.end());
  const Window densest = densest_window(sorted);
  if (densest.count == 0 || 2 * densest.count < sorted.size() ||
      sorted.size() - densest.count >= kMinMovingSamples)
    return {};
  const double centre = sorted[densest.begin + densest.count / 2];
  MixtureParams p = initial_params(work, {centre}, vmax);
  const double ll = run_em(work, p, kEmIterations, 1e-6);
  if (p.gears() != 1 || judge.check(p).offender >= 0) return {};
  if (std::abs(std::log(p.theta[0]) - centre) > kGearWindow) return {};  // EM left the cluster
  return {p, ll, bic_of(ll, 1, work.size())};
}

// The gears below the chosen ladder that a plausible ladder of more gears held (BIC judged their pairs too
// few to pay for them: a launch passes first gear in a second or two), as `extra.lower_gears`, ascending.
// The synthesis takes them for the gears a ladder that lacks first gear has below it, where it would
// otherwise predict them from the ladder's steps.
void record_lower_gears(const std::vector<double>& largest, GearModel& fitted) {
  if (fitted.gears.empty()) return;
  const double below = fitted.gears.front().theta * std::exp(-2.0 * kGearWindow);
  std::vector<double> lower;
  for (const double theta : largest)
    if (theta < below) lower.push_back(theta);
  std::sort(lower.begin(), lower.end());
  if (!lower.empty()) fitted.extra["lower_gears"] = lower;
}

// A manual car moves off in first gear, which carries it at the warm idle at kFirstGearIdleSpeed at most.
// A chosen ladder whose lowest gear carries it faster lacks first gear: that gear exists whatever the number
// of its pairs, and what BIC weighs (whether a gear's pairs pay for its parameters) is then no question. A
// launch passes first gear in a second or two, and where the pairs of those seconds are spread (OBD values
// polled apart while the car gains 2-3 m/s^2 spread its ratios by 20-30 %) the gear gains less than BIC
// asks. Where a plausible ladder met on the way down (every check passed: support, steps, valleys, clutch
// slip) holds the chosen ladder's gears and more below them, the lowest of which can be first gear, the
// best of those by BIC is the fit. A ladder whose lowest gear can be first gear stays as BIC chose it, and
// nothing is added that the checks rejected.
Candidate with_first_gear(const Candidate& best, const std::vector<Candidate>& plausible, double idle_freq) {
  const std::vector<double>& chosen_theta = best.params.theta;
  if (chosen_theta.size() < 2 || !(idle_freq > 0.0) ||
      chosen_theta.front() * idle_freq <= kFirstGearIdleSpeed)
    return best;
  const double below = chosen_theta.front() * std::exp(-2.0 * kGearWindow);  // a gearbox step below
  const Candidate* completed = nullptr;
  for (const Candidate& c : plausible) {
    const std::vector<double>& theta = c.params.theta;
    if (theta.size() <= chosen_theta.size() || theta.front() * idle_freq > kFirstGearIdleSpeed) continue;
    const auto lower = static_cast<std::size_t>(std::lower_bound(theta.begin(), theta.end(), below) -
                                                theta.begin());  // gears below the chosen
    if (theta.size() - lower != chosen_theta.size()) continue;
    bool same = true;
    for (std::size_t i = 0; i < chosen_theta.size(); ++i)
      same = same && std::abs(std::log(theta[lower + i] / chosen_theta[i])) < kGearWindow;
    if (same && (completed == nullptr || c.bic < completed->bic)) completed = &c;
  }
  return completed != nullptr ? *completed : best;
}

}  // namespace

GearModel fit_auto(const MixtureData& input, int gears, bool single_gear) {
  const Aligned aligned = aligned_channels(input);
  const MixtureData& all = aligned.data;
  GearModel model;
  model.method = "auto";
  model.extra["speed_lag"] = aligned.lag;
  model.samples = all.size();
  std::vector<double> log_ratios;
  double vmax = 0.0;
  for (std::size_t k = 0; k < all.size(); ++k) {
    vmax = std::max(vmax, all.v[k]);
    if (all.v[k] > kMovingSpeed) log_ratios.push_back(std::log(all.v[k] / all.s[k]));
  }
  if (log_ratios.size() < kMinMovingSamples) {
    model.reason =
        all.size() == 0 ? "no samples with both speed and frequency" : "too few samples while moving";
    return model;
  }
  bool timed = false;
  std::vector<double> steady = steady_log_ratios(all, timed);
  // In gear the ratio holds from one sample to the next. A timed log in which hardly any sample agrees
  // with a neighbour has no engaged gear to learn from: noise, or two channels that do not belong
  // together (real drives: most moving samples agree; shifts and clutch make the rest).
  constexpr double kMinSteadyShare = 0.1;
  if (timed &&
      static_cast<double>(steady.size()) < kMinSteadyShare * static_cast<double>(log_ratios.size())) {
    model.reason =
        "the speed/frequency ratio hardly ever holds from one sample to the next (no gear engaged)";
    return model;
  }
  if (steady.size() < kMinMovingSamples) steady = log_ratios;
  const MixtureData work = subsample(all, kWorkingSamples);
  const LadderJudge judge(work, all.size(), steady, log_ratios);
  std::vector<double> init =
      candidate_scales(steady, static_cast<std::size_t>(std::max(kMaxCandidates, gears)));
  // A forced count larger than the modes found: fill the widest gaps geometrically.
  while (static_cast<int>(init.size()) < gears) {
    std::sort(init.begin(), init.end());
    std::size_t widest = 0;
    for (std::size_t i = 1; i + 1 < init.size(); ++i)
      if (init[i + 1] - init[i] > init[widest + 1] - init[widest]) widest = i;
    init.push_back(init.size() < 2 ? init[0] + 0.3 : 0.5 * (init[widest] + init[widest + 1]));
  }
  // Backward elimination: fit all candidates, then drop one component at a time (an implausible one
  // first, else the lightest), refitting each time; keep the plausible ladder of best BIC.
  MixtureParams p = initial_params(work, init, vmax);
  Candidate best;
  std::string last_reason = "no discrete gear ladder in the data";
  LadderCheck forced;  // what the physics says of a forced count's ladder
  Candidate more;      // with a forced count: the best plausible ladder of more gears met on the way down
  std::vector<double> largest;       // the thetas of the plausible ladder of most gears met on the way down
  std::vector<Candidate> plausible;  // the plausible ladders met on the way down
  while (true) {
    const double ll = run_em(work, p, kEmIterations, 1e-6);
    const LadderCheck verdict = judge.check(p);
    const int m = p.gears();
    if (gears > 0 && m == gears) {
      more = best;
      best = {p, ll, bic_of(ll, m, work.size())};
      forced = verdict;
      break;
    }
    if (verdict.offender < 0 && m >= 2) {
      if (largest.empty()) largest = p.theta;
      const double bic = bic_of(ll, m, work.size());
      if (gears == 0) plausible.push_back({p, ll, bic});
      if (bic < best.bic) best = {p, ll, bic};
    } else if (!verdict.reason.empty()) {
      last_reason = verdict.reason;
    }
    if (m <= std::max(gears, 1)) break;
    int drop = verdict.offender;
    if (drop < 0) drop = static_cast<int>(std::min_element(p.alpha.begin(), p.alpha.end()) - p.alpha.begin());
    p = without(p, drop);
  }
  if (best.params.gears() == 0 && single_gear && gears == 0) best = single_cluster(work, steady, judge, vmax);
  if (gears == 0) best = with_first_gear(best, plausible, judge.idle_freq());
  if (best.params.gears() == 0) {
    model.reason = last_reason;
    return model;
  }
  p = best.params;
  // The subsample chose the ladder; the full data sets the final values.
  if (work.size() < all.size()) (void)run_em(all, p, kFullDataIterations, 1e-9, false);
  GearModel fitted = finish_model(all, p, "auto", GradientLayout{p.gears(), true, p.beta_stand > 0.0});
  fitted.extra["speed_lag"] = aligned.lag;
  if (gears == 0) record_lower_gears(largest, fitted);
  // A forced count is fitted whatever the data shows, but not silently: the ladder's first failing gear
  // and why (a near-empty gear added beside the real ones, clusters too close or too far apart), or the
  // larger plausible ladder that explains the data better (a real gear merged away).
  if (forced.offender >= 0 && static_cast<std::size_t>(forced.offender) < fitted.gears.size()) {
    char what[64];
    std::snprintf(what, sizeof what, "gear %d (theta %.5f): ", forced.offender + 1,
                  fitted.gears[static_cast<std::size_t>(forced.offender)].theta);
    fitted.extra["forced_doubt"] = {{"gear", forced.offender + 1}, {"reason", what + forced.reason}};
  } else if (more.bic < best.bic) {
    fitted.extra["forced_doubt"] = {
        {"gears", more.params.gears()},
        {"reason", std::to_string(more.params.gears()) + " gears explain the data better (BIC)"}};
  }
  return fitted;
}

}  // namespace gearpulse::detail

namespace gearpulse {

std::vector<double> steady_log_ratios(std::span<const Sample> samples) {
  detail::MixtureData data;
  for (const Sample& s : samples) {
    if (!s.has_speed() || !s.has_freq() || s.speed < 0.0 || s.freq <= 0.0) continue;
    data.v.push_back(s.speed);
    data.s.push_back(s.freq);
    data.t.push_back(s.t);
  }
  bool timed = false;
  std::vector<double> out = detail::steady_log_ratios(data, timed);
  std::sort(out.begin(), out.end());
  return out;
}

std::size_t largest_gear_cluster(std::span<const double> sorted_log_ratios) {
  return detail::densest_window(sorted_log_ratios).count;
}

}  // namespace gearpulse
