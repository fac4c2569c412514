#include "core/sliding_dft_tracker_evidence.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <iterator>
#include <numbers>

namespace gearpulse {
namespace {

// Table axes: log10 of the per-bin SNR rho, and sqrt(z) (fine steps where z is small).
constexpr double kLogRhoLo = -1.0, kLogRhoHi = 4.0;
constexpr double kRhoHi = 1e4;  // 10^kLogRhoHi
constexpr int kRhoSteps = 50;
constexpr double kUMax = 45.0;  // z up to ~2000; beyond, the ratios are flat (bounded by the tone prior)
constexpr int kUSteps = 450;
// Broad prior of an engine line's per-bin SNR: log-uniform over 1 .. 1e4 (about -10 to +30 dB in the
// 50-200 Hz band with a 100 ms window).
constexpr double kBroadLo = 1.0, kBroadHi = 1e4;
constexpr int kBroadSteps = 80;
// Weight of the matched (track-level) SNR against the broad prior for the fundamental.
constexpr double kMatched = 0.5;
// Order-to-fundamental power ratio r (the callers carry the fundamental's per-bin SNR to the order's bin
// through the two floors): log-uniform over 0.03 .. 2 (-15 to +3 dB) for the harmonics (the 2nd falls to
// about -15 dB at full load), up to 0.5 for the half order (a "half order" stronger than the fundamental
// means the candidate is the engine's 2nd harmonic), or the order absent altogether.
constexpr double kRatioLo = 0.03, kRatioHi = 2.0, kHalfRatioHi = 0.5;
// The 2nd harmonic of a four-stroke's firing frequency takes the fundamental's energy at light load and on
// the overrun, where it stands up to 15 dB over it. Its ratio is drawn from a mixture: with probability
// 1 - kLoudSecond as the other harmonics', with kLoudSecond log-uniform over 2 .. 30 (+3 to +15 dB). A
// proper prior, not the better of two: a loud 2nd harmonic costs ln kLoudSecond against a usual one, so
// a candidate's sub-harmonic (whose 2nd harmonic is the engine's fundamental) is not lifted for free.
// kLoudSecond, the share of light load and overrun, is chosen on the generated scenes' tuning set. On the
// overrun itself (a line falling fast: the engine does not drive the car) the 2nd harmonic is as likely
// loud as not: kLoudSecondOverrun. Under power (a line rising fast: the engine drives the car hard) the
// fundamental takes the firing energy and a 2nd harmonic over it is rare: kLoudSecondPower, chosen on the
// tuning set (0.02 and 0.05).
constexpr double kSecondRatioHi = 30.0;
constexpr double kLoudSecond = 0.15;
constexpr double kLoudSecondOverrun = 0.5;
constexpr double kLoudSecondPower = 0.02;
constexpr int kRatioSteps = 20;
// A line below a candidate f that is an order of a lower engine of which f is a harmonic (a comb): its ratio
// to f's line (per-bin SNRs, each against its own floor), log-uniform over 0.03 .. 1000 (-15 to +30 dB): a
// clean idle's fundamental and 3rd stand up to 30 dB over its 4th harmonic, as an ignition comb's do.
constexpr double kLowerRatioHi = 1000.0;
// Probabilities of the half order's absence tabulated for half_order(): the prior's, then as learned.
constexpr double kHalfAbsent[] = {HarmonicEvidence::kOrderAbsent, 0.1, 0.3, 0.6, 0.9};
constexpr int kHalfTables = static_cast<int>(std::size(kHalfAbsent));
constexpr int kProfileTables = static_cast<int>(std::size(HarmonicEvidence::kProfileSpreadDb));

double log_i0(double x) {
  if (x < 20.0) {
    double sum = 1.0, term = 1.0;
    for (int k = 1; k < 80; ++k) {
      term *= (x / (2.0 * k)) * (x / (2.0 * k));
      sum += term;
      if (term < 1e-17 * sum) break;
    }
    return std::log(sum);
  }
  return x - 0.5 * std::log(2.0 * std::numbers::pi * x) + std::log1p(1.0 / (8.0 * x) + 9.0 / (128.0 * x * x));
}

double log_rice(double z, double rho) {
  return -(z + rho) + log_i0(2.0 * std::sqrt(rho * z));
}

double log_add(double a, double b) {
  const double m = std::max(a, b);
  return m + std::log(std::exp(a - m) + std::exp(b - m));
}

// log of the mean of exp(f(rho)) over rho log-uniform in [lo, hi]: steps + 1 points in ln(rho), each
// standing for a cell of its width, and the three cells around the integrand's peak integrated on a fine
// grid. A loud bin's likelihood is a narrow peak in rho (its width in ln(rho) about 2 / sqrt(z), 4 % at
// z = 2000), far narrower than a cell; sampled at the grid points alone it was missed or hit by chance,
// and the ratios of a clean line came out small or negative.
template <class F>
double log_mean_over(double lo, double hi, int steps, F f) {
  constexpr int kMaxSteps = 128, kFine = 48;  // fine points over the three cells around the peak
  steps = std::clamp(steps, 1, kMaxSteps);
  const double h = std::log(hi / lo) / steps, x0 = std::log(lo);
  std::array<double, kMaxSteps + 1> at{};
  int peak = 0;
  for (int i = 0; i <= steps; ++i) {
    at[static_cast<std::size_t>(i)] = f(std::exp(x0 + i * h));
    if (at[static_cast<std::size_t>(i)] > at[static_cast<std::size_t>(peak)]) peak = i;
  }
  double acc = -INFINITY;
  for (int i = 0; i <= steps; ++i)
    if (std::abs(i - peak) > 1) acc = log_add(acc, at[static_cast<std::size_t>(i)]);
  // The cells of points peak-1 .. peak+1 (those that exist), [first - h/2, last + h/2], in units of cells.
  const double from = std::max(peak - 1, 0) - 0.5, to = std::min(peak + 1, steps) + 0.5;
  const double dx = (to - from) / kFine;
  for (int k = 0; k < kFine; ++k)
    acc = log_add(acc, std::log(dx) + f(std::exp(x0 + (from + (k + 0.5) * dx) * h)));
  return acc - std::log(steps + 1.0);
}

double rho_of(int i) {
  return std::pow(10.0, kLogRhoLo + (kLogRhoHi - kLogRhoLo) * i / kRhoSteps);
}

}  // namespace

const HarmonicEvidence& HarmonicEvidence::shared() {
  static const HarmonicEvidence instance(0.05);
  return instance;
}

HarmonicEvidence::HarmonicEvidence(double tone_prior) {
  const double log_tone = std::log(tone_prior), log_no_tone = std::log1p(-tone_prior);
  const auto cols = static_cast<std::size_t>(kUSteps + 1);
  fund_.assign(static_cast<std::size_t>(kRhoSteps + 1) * cols, 0.0);
  constexpr auto track = static_cast<std::size_t>(Level::kTrack),
                 read = static_cast<std::size_t>(Level::kRead);
  std::vector<double>& ladder_table = ladder_[track];
  std::vector<double>& usual_table = second_[track];
  std::vector<double>& overrun_table = second_overrun_[track];
  std::vector<double>& power_table = second_power_[track];
  ladder_table.assign(fund_.size(), 0.0);
  usual_table.assign(fund_.size(), 0.0);
  overrun_table.assign(fund_.size(), 0.0);
  power_table.assign(fund_.size(), 0.0);
  lower_.assign(fund_.size(), 0.0);
  half_.assign(kHalfTables, std::vector<double>(fund_.size(), 0.0));
  profile_.assign(kProfileTables, std::vector<double>(fund_.size(), 0.0));
  for (int j = 0; j <= kUSteps; ++j) {
    const double u = kUMax * j / kUSteps, z = u * u;
    const double log_broad =
        log_mean_over(kBroadLo, kBroadHi, kBroadSteps, [z](double r) { return log_rice(z, r); });
    const double log_background = log_add(log_no_tone - z, log_tone + log_broad);
    for (int i = 0; i <= kRhoSteps; ++i) {
      const double rho = rho_of(i);
      const std::size_t at = static_cast<std::size_t>(i) * cols + static_cast<std::size_t>(j);
      fund_[at] =
          log_add(std::log(kMatched) + log_rice(z, rho), std::log1p(-kMatched) + log_broad) - log_background;
      const auto with_absent = [&](double log_ratio, double absent) {
        const double engine = log_add(std::log1p(-absent) + log_ratio, std::log(absent) - z);
        return log_add(log_no_tone + engine, log_tone + log_broad) - log_background;
      };
      const auto log_ratio = [&](double hi) {
        return log_mean_over(kRatioLo, hi, kRatioSteps, [z, rho](double r) { return log_rice(z, rho * r); });
      };
      ladder_table[at] = with_absent(log_ratio(kRatioHi), kOrderAbsent);
      const double loud = log_mean_over(kRatioHi, kSecondRatioHi, kRatioSteps,
                                        [z, rho](double r) { return log_rice(z, rho * r); });
      const double usual = log_ratio(kRatioHi);
      const auto second = [&](double share) {
        return with_absent(log_add(std::log1p(-share) + usual, std::log(share) + loud), kOrderAbsent);
      };
      usual_table[at] = second(kLoudSecond);
      overrun_table[at] = second(kLoudSecondOverrun);
      power_table[at] = second(kLoudSecondPower);
      lower_[at] = with_absent(log_ratio(kLowerRatioHi), kOrderAbsent);
      const double half_ratio = log_ratio(kHalfRatioHi);
      for (int n = 0; n < kHalfTables; ++n)
        half_[static_cast<std::size_t>(n)][at] = with_absent(half_ratio, kHalfAbsent[n]);
      // A ratio normal in dB about 0 dB, over +-4 spreads: the mean over ln r of Rice x the normal density,
      // times the range (a uniform mean over it).
      for (int n = 0; n < kProfileTables; ++n) {
        const double s = kProfileSpreadDb[n] * std::numbers::ln10 / 10.0, range = 8.0 * s;
        const double log_norm = -0.5 * std::log(2.0 * std::numbers::pi * s * s) + std::log(range);
        const double normal =
            log_mean_over(std::exp(-4.0 * s), std::exp(4.0 * s), kRatioSteps, [&](double r) {
              const double x = std::log(r) / s;
              return log_rice(z, rho * r) + log_norm - 0.5 * x * x;
            });
        profile_[static_cast<std::size_t>(n)][at] = with_absent(normal, kOrderAbsent);
      }
    }
  }
  // The same terms for a level read from one bin (Level::kRead): the mean of each term's likelihood over
  // the reading's scatter, the line's amplitude sqrt(rho) normal about the reading's with a standard
  // deviation of sqrt(1/2) (a complex Gaussian noise of unit power), by the three-point Gauss-Hermite rule
  // (nodes at 0 and +-sqrt(3) standard deviations, weights 2/3 and 1/6); a level below the table's lowest
  // (0.1) is read there.
  const auto over_scatter = [&](const std::vector<double>& table) {
    std::vector<double> out(table.size());
    for (int i = 0; i <= kRhoSteps; ++i) {
      const double rho = rho_of(i), amp = std::sqrt(rho), d = std::sqrt(3.0 * 0.5);
      const double lo = std::max((amp - d) * std::max(amp - d, 0.0), rho_of(0)), hi = (amp + d) * (amp + d);
      for (int j = 0; j <= kUSteps; ++j) {
        const double u = kUMax * j / kUSteps, z = u * u;
        const std::size_t at = static_cast<std::size_t>(i) * cols + static_cast<std::size_t>(j);
        const double a = lookup(table, z, lo), m = table[at], b = lookup(table, z, hi);
        const double top = std::max({a, m, b});
        out[at] = top + std::log((std::exp(a - top) + 4.0 * std::exp(m - top) + std::exp(b - top)) / 6.0);
      }
    }
    return out;
  };
  ladder_[read] = over_scatter(ladder_table);
  second_[read] = over_scatter(usual_table);
  second_overrun_[read] = over_scatter(overrun_table);
  second_power_[read] = over_scatter(power_table);
}

double HarmonicEvidence::lookup(const std::vector<double>& table, double z, double rho) const noexcept {
  // Beyond the table (a bin louder than ~33 dB over the noise), the ratios are saturated: z and rho are
  // scaled down together, so a loud line is read at the table's edge with its level against the expected
  // one kept, rather than with one of the two clamped (a clean line then read as mismatched to itself).
  if (const double k = std::max({1.0, z / (kUMax * kUMax), rho / kRhoHi}); k > 1.0) {
    z /= k;
    rho /= k;
  }
  const double u = std::clamp(std::sqrt(std::max(z, 0.0)) / kUMax * kUSteps, 0.0, kUSteps - 1e-9);
  const double lr = std::isfinite(rho) && rho > 0.0 ? std::log10(rho) : kLogRhoLo;
  const double r = std::clamp((lr - kLogRhoLo) / (kLogRhoHi - kLogRhoLo) * kRhoSteps, 0.0, kRhoSteps - 1e-9);
  const auto j = static_cast<std::size_t>(u), i = static_cast<std::size_t>(r);
  const double a = u - static_cast<double>(j), b = r - static_cast<double>(i);
  const auto cols = static_cast<std::size_t>(kUSteps + 1);
  const double* row0 = table.data() + i * cols;
  const double* row1 = row0 + cols;
  return (1.0 - b) * ((1.0 - a) * row0[j] + a * row0[j + 1]) + b * ((1.0 - a) * row1[j] + a * row1[j + 1]);
}

double HarmonicEvidence::fundamental(double z, double rho_track) const noexcept {
  return lookup(fund_, z, rho_track);
}

double HarmonicEvidence::order(double z, double rho_fundamental, Level level) const noexcept {
  return lookup(ladder_[static_cast<std::size_t>(level)], z, rho_fundamental);
}

double HarmonicEvidence::second(double z, double rho_fundamental, Level level) const noexcept {
  return lookup(second_[static_cast<std::size_t>(level)], z, rho_fundamental);
}

double HarmonicEvidence::second_overrun(double z, double rho_fundamental, Level level) const noexcept {
  return lookup(second_overrun_[static_cast<std::size_t>(level)], z, rho_fundamental);
}

double HarmonicEvidence::second_power(double z, double rho_fundamental, Level level) const noexcept {
  return lookup(second_power_[static_cast<std::size_t>(level)], z, rho_fundamental);
}

double HarmonicEvidence::lower_root(double z, double rho_line) const noexcept {
  return lookup(lower_, z, rho_line);
}

double HarmonicEvidence::between(const std::vector<std::vector<double>>& tables, std::span<const double> keys,
                                 double key, double z, double rho) const noexcept {
  const int last = static_cast<int>(keys.size()) - 1;
  key = std::clamp(key, keys[0], keys[static_cast<std::size_t>(last)]);
  int n = 0;
  while (n + 1 < last && key > keys[static_cast<std::size_t>(n + 1)])
    ++n;
  const auto i = static_cast<std::size_t>(n);
  const double w = (key - keys[i]) / (keys[i + 1] - keys[i]);
  if (w <= 0.0) return lookup(tables[i], z, rho);
  return (1.0 - w) * lookup(tables[i], z, rho) + w * lookup(tables[i + 1], z, rho);
}

double HarmonicEvidence::half_order(double z, double rho_fundamental, double absent) const noexcept {
  return between(half_, kHalfAbsent, absent, z, rho_fundamental);
}

double HarmonicEvidence::profiled(double z, double rho, double spread_db) const noexcept {
  return between(profile_, kProfileSpreadDb, spread_db, z, rho);
}

}  // namespace gearpulse
