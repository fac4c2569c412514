// Auto fit, the candidates: gear scales from the modes of the density of log(v/s) (of the steady samples,
// those that agree with a time neighbour), and the judge of what the physics of a gearbox asks of a fitted
// ladder beyond the likelihood (support, steps, valleys, clutch slip).
#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>
#include <span>

#include "core/auto_estimator_internal.hpp"
#include "core/estimator.hpp"

namespace gearpulse::detail {
namespace {

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

}  // namespace

LadderJudge::LadderJudge(const MixtureData& work, std::size_t total_samples,
                         std::vector<double> steady_log_ratios, std::vector<double> moving_log_ratios,
                         std::vector<double> octave_log_ratios)
    : work_(work),
      total_(total_samples),
      log_ratios_(std::move(steady_log_ratios)),
      moving_(std::move(moving_log_ratios)),
      octave_(std::move(octave_log_ratios)) {
  std::sort(log_ratios_.begin(), log_ratios_.end());
  std::sort(octave_.begin(), octave_.end());
  std::sort(moving_.begin(), moving_.end());
  // The idle frequency, from standstill samples, if the log has enough of them.
  constexpr std::size_t kMinIdleSamples = 20;
  if (const auto idle = estimate_idle(work, kMinIdleSamples)) idle_freq_ = idle->freq;
}

LadderCheck LadderJudge::check(const MixtureParams& p) const {
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
  // The frequency tracker locks for a moment now and then on the line at twice or half the engine's
  // (tracker-method.md): a gear read so gives a reading at half or twice its theta beside time neighbours
  // read right. A gear is held, and its readings agree with their neighbours'; a cluster with more
  // readings at twice or half a neighbour's frequency than readings that agree with a neighbour is a
  // gear's other line (with the shifts' transients that fall beside it), not a gear. Each cluster is read
  // within half the log step to its nearest neighbour. The lowest gear is not judged so: it is passed
  // through in a second or two on every launch, its readings beside the 1 -> 2 shift, whose step is near
  // two in many gearboxes.
  for (int i = 1; i < m; ++i) {
    const double down = std::log(p.theta[i] / p.theta[i - 1]);
    const double w = 0.5 * (i + 1 < m ? std::min(down, std::log(p.theta[i + 1] / p.theta[i])) : down);
    const double c = std::log(p.theta[i]);
    if (count_in(octave_, c - w, c + w) > count_in(log_ratios_, c - w, c + w))
      return {i,
              "a cluster of readings at twice or half a time neighbour's engine frequency (the tracker "
              "on another line of a gear)"};
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

std::size_t LadderJudge::count_in(const std::vector<double>& sorted, double lo, double hi) {
  return static_cast<std::size_t>(std::upper_bound(sorted.begin(), sorted.end(), hi) -
                                  std::lower_bound(sorted.begin(), sorted.end(), lo));
}

std::size_t LadderJudge::count_in(double lo, double hi) const {
  return count_in(log_ratios_, lo, hi);
}

double LadderJudge::steady_support(double centre, double half_width) const {
  return static_cast<double>(count_in(centre - half_width, centre + half_width));
}

// The steady ratios decide where they show both clusters. A gear held for less than the log's sample
// interval (first gear at 0.5 Hz: a second or two per launch) leaves few samples that agree with a
// neighbour; then all moving ratios decide (a cluster's own samples and the valley beside it).
bool LadderJudge::valley_between(double a, double b) const {
  return valley_in(log_ratios_, a, b).value_or(valley_in(moving_, a, b).value_or(false));
}

// Whether a valley lies between the peaks at a and b; nothing when a peak has too few samples to tell.
std::optional<bool> LadderJudge::valley_in(const std::vector<double>& sorted, double a, double b) {
  const double w = (b - a) / 6.0;
  const double peak =
      static_cast<double>(std::min(count_in(sorted, a - w, a + w), count_in(sorted, b - w, b + w)));
  if (peak < 6.0) return std::nullopt;
  const double mid = 0.5 * (a + b);
  return static_cast<double>(count_in(sorted, mid - w, mid + w)) < 0.5 * peak;
}

LadderJudge::FreqSpread LadderJudge::freq_spread(const MixtureParams& p, int gear) const {
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

namespace {

// log(v/s) of the moving samples whose ratio, moved by `shift` either way, agrees with a time neighbour's;
// `timed` false, and none, without usable time stamps.
std::vector<double> agreeing_log_ratios(const MixtureData& all, double shift, bool& timed) {
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
  if (gaps.empty() || gaps.size() < n / 2) return out;
  timed = true;
  std::nth_element(gaps.begin(), gaps.begin() + static_cast<std::ptrdiff_t>(gaps.size() / 2), gaps.end());
  const double max_gap = 3.0 * gaps[gaps.size() / 2];
  auto agree = [&](std::size_t k, std::size_t j, double r) {
    if (!moving(j) || std::abs(all.t[j] - all.t[k]) > max_gap) return false;
    const double rj = std::log(all.v[j] / all.s[j]);
    return steady_ratios_agree(r + shift, rj, all.v[k]) || steady_ratios_agree(r - shift, rj, all.v[k]);
  };
  for (std::size_t k = 0; k < n; ++k) {
    if (!moving(k)) continue;
    const double r = std::log(all.v[k] / all.s[k]);
    if ((k > 0 && agree(k, k - 1, r)) || (k + 1 < n && agree(k, k + 1, r))) out.push_back(r);
  }
  return out;
}

}  // namespace

// log(v/s) of the moving samples that agree with a time neighbour: a sample in gear shares its ratio with
// the sample before or after it, while shifts, clutch slip and an OBD logger's skewed polls give isolated
// ratios. The tolerance widens at low speed where a few tenths of m/s of speed error (GPS noise, integer
// km/h) move the ratio. Without usable time stamps every moving sample counts.
std::vector<double> steady_log_ratios(const MixtureData& all, bool& timed) {
  std::vector<double> out = agreeing_log_ratios(all, 0.0, timed);
  if (timed) return out;
  for (std::size_t k = 0; k < all.size(); ++k)
    if (all.v[k] > kMovingSpeed) out.push_back(std::log(all.v[k] / all.s[k]));
  return out;
}

// log(v/s) of the moving samples read at twice or half a time neighbour's frequency (their ratio moved by
// ln 2 agrees with the neighbour's); none without time stamps.
std::vector<double> octave_log_ratios(const MixtureData& all) {
  bool timed = false;
  return agreeing_log_ratios(all, std::numbers::ln2, timed);
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

}  // namespace gearpulse
