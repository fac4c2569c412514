#pragma once
// Likelihood ratios of the engine's harmonic ladder in one windowed spectrum, used by SlidingDftTracker
// to weigh every candidate fundamental frequency.
//
// The observation at one spectral bin is z = |X|^2 / (noise floor): exponential with mean 1 on noise
// alone, non-central (Rice) with per-bin SNR rho when a line is there:
//   p(z | rho) = exp(-(z + rho)) I0(2 sqrt(rho z)).
// A bin the engine does not explain is noise or, with probability `tone_prior`, a line of other equipment
// (fan, pump) of unknown strength; under the engine hypothesis such a line may still sit on any bin. So
// the ratio of one bin is bounded by about 1 / tone_prior: a loud line proves no more than that
// something is there. The fundamental's SNR is expected near the track's recent level (a matched test,
// the longer integration a steady engine allows) or anywhere over a broad range (acquisition, level
// changes). The other orders (f/2, 2f, 3f) are expected at a fraction r of the fundamental's SNR, r
// unknown over two decades (the 2nd harmonic's up to +15 dB) or known about a learned ratio, or absent: a
// loud line whose harmonics are all missing is unlikely to be the engine; a weak one whose harmonics drown in
// the noise is not penalised. Some signals have no half order at all: the probability of its absence can be
// given as learned (half_order()).
//
// Everything is tabulated at construction; lookups are noexcept and allocation-free.
#include <array>
#include <span>
#include <vector>

namespace gearpulse {

class HarmonicEvidence {
 public:
  // How the fundamental's per-bin SNR, which scales the other orders' level priors, is known: the track's
  // level (smoothed over hops), or read from the candidate's own bin in this window (z - 1). A reading
  // scatters by the bin's noise: its amplitude sqrt(z) about the line's sqrt(rho) with a standard deviation
  // of about sqrt(1/2) (Rice), so at -5 dB (rho about 5) one window's reading lies anywhere from 1 to 12,
  // and an order scaled by a low reading (a fundamental faded at light load under a loud 2nd harmonic)
  // is judged too loud. For a read level the terms average their likelihood over that scatter.
  enum class Level { kTrack, kRead };
  // Prior probability that an order other than the fundamental is absent (half_order() takes a learned one).
  static constexpr double kOrderAbsent = 0.03;
  // The tables for the default tone prior, built once (thread-safe) and shared by every tracker.
  static const HarmonicEvidence& shared();
  explicit HarmonicEvidence(double tone_prior);
  // Log likelihood ratio (engine fundamental over noise-or-tone) of a bin with normalised power z, when
  // the track's recent fundamental SNR is rho_track (per bin, linear).
  [[nodiscard]] double fundamental(double z, double rho_track) const noexcept;
  // Log likelihood ratio of a harmonic's bin (2f, 3f), given the per-bin SNR that the candidate's
  // fundamental would have in that bin (its own times the ratio of the two bins' floors: the level prior
  // is a ratio of the lines' powers).
  [[nodiscard]] double order(double z, double rho_fundamental, Level level) const noexcept;
  // The same for the 2nd harmonic's bin, which may stand up to 15 dB over the fundamental (light load,
  // overrun).
  [[nodiscard]] double second(double z, double rho_fundamental, Level level) const noexcept;
  // The same on the overrun (engine braking: a line falling fast), where the 2nd harmonic is as likely to
  // stand over the fundamental as not.
  [[nodiscard]] double second_overrun(double z, double rho_fundamental, Level level) const noexcept;
  // The same under power (a line rising fast: the engine drives the car hard), where the fundamental
  // takes the firing energy and a 2nd harmonic over it is rare.
  [[nodiscard]] double second_power(double z, double rho_fundamental, Level level) const noexcept;
  // The same for a bin below a candidate's line that is an order of a lower engine of which the candidate
  // is a harmonic (f / 4 and 3 f / 4 when it is the 4th), given the per-bin SNR of the candidate's line:
  // the ratio spans 0.03 .. 1000 (-15 to +30 dB).
  [[nodiscard]] double lower_root(double z, double rho_line) const noexcept;
  // The same for the half order's bin, when the probability that this engine's signal has none is
  // `absent` (learned per recording; the prior's is kOrderAbsent), within [kOrderAbsent, 0.9].
  [[nodiscard]] double half_order(double z, double rho_fundamental, double absent) const noexcept;
  // The same for an order's bin whose level is known: its per-bin SNR normal in dB about rho_expected
  // (the fundamental's times a ratio learned from this engine) with `spread_db` (clamped to
  // kProfileSpreadDb's range), or the order absent (kOrderAbsent).
  [[nodiscard]] double profiled(double z, double rho_expected, double spread_db) const noexcept;
  // Spreads (dB) of the tabulated profiles; profiled() interpolates between them.
  static constexpr double kProfileSpreadDb[] = {2.0, 4.0, 8.0};

 private:
  [[nodiscard]] double lookup(const std::vector<double>& table, double z, double rho) const noexcept;
  // A lookup interpolated between the tables of the two `keys` (ascending, one per table) about `key`,
  // clamped to their range.
  [[nodiscard]] double between(const std::vector<std::vector<double>>& tables, std::span<const double> keys,
                               double key, double z, double rho) const noexcept;
  std::vector<double> fund_;   // over (log10 rho, sqrt z)
  std::vector<double> lower_;  // over (log10 rho, sqrt z)
  // Per Level (kTrack, kRead), over (log10 rho, sqrt z):
  std::array<std::vector<double>, 2> ladder_;
  std::array<std::vector<double>, 2> second_;
  std::array<std::vector<double>, 2> second_overrun_;
  std::array<std::vector<double>, 2> second_power_;
  // The half order's, one table per probability of its absence (kHalfAbsent, the first kOrderAbsent), for a
  // level known either way: averaged over a read level's scatter too, it lets a drive with weak orders and a
  // loud fixed tone be read off every order of its engine for seconds (docs/algorithms/tracker-method.md,
  // "The orders' level read with its scatter").
  std::vector<std::vector<double>> half_;
  // One table per kProfileSpreadDb, the ratio's mean at 0 dB, over (log10 rho, sqrt z).
  std::vector<std::vector<double>> profile_;
};

}  // namespace gearpulse
