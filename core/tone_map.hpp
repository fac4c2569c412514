#pragma once
// Fixed tones of other equipment (a fan's or a pump's line) that the engine-frequency tracker counts as
// background: per fine spectral bin, the mean normalised power (1 on noise) over the last tens of
// seconds. The same mean corrects a noise floor set above a bin's noise. A line that stays put while the
// engine moves raises its bin's mean; the bins near the track's orders are not learned while the track holds
// them, so a cruising engine does not become a tone. Sized at construction; nothing allocates, locks or
// throws afterwards.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <span>
#include <vector>

namespace gearpulse {

class ToneMap {
 public:
  // Mean normalised power from which a learned tone counts (and is fitted along with the engine's orders).
  static constexpr double kFitLevel = 4.0;
  // The lowest background: a bin's mean below 1 is a floor read over its noise, which the lower quartile of
  // a block does when a resonance's skirt or other lines fill part of it (1-2.5 dB on the generated scenes);
  // a floor more than 3 dB over a bin's readings is the leakage of loud lines, not a biased noise level.
  static constexpr double kLowestNoise = 0.5;

  // bins: fine bins of the spectrum; learned over first..last; lobe fine bins to a resolution bin of
  // df_hz x lobe Hz; one window every hop_s.
  ToneMap(std::size_t bins, int first, int last, int lobe, double df_hz, double hop_s);

  void reset() noexcept;
  [[nodiscard]] std::size_t bins() const noexcept { return tone_.size(); }
  // The bin's mean normalised power.
  [[nodiscard]] double mean(std::size_t k) const noexcept { return tone_[k]; }
  // What a reading of the bin is divided by: the tone's level where it stands above the noise on average
  // (a moving engine raises a bin's mean a little, not a lot), but up to kFitLevel only where the engine's
  // lines may stand (see mark()) unless the bin is a learned tone: a loud engine's own line held in a bin
  // raises its mean far past kFitLevel, and divided by that mean the engine's readings there read as noise;
  // the mean itself (from kLowestNoise) where it is below 1: lines only add power, so a bin that reads under
  // the floor on average lies under a floor set too high, and its readings divided by that mean read as
  // noise again; else 1.
  [[nodiscard]] double background(std::size_t k) const noexcept {
    if (tone_[k] < 1.0) return std::max(tone_[k], kLowestNoise);
    return std::max(1.0, (learned(k) || !engine_[k] ? tone_[k] : std::min(tone_[k], kFitLevel)) - 1.0);
  }
  // Within one resolution bin of a learned tone (a mean from kFitLevel, its line having stayed put while
  // the estimate moved; see learn()), as marked by mark() for this hop.
  [[nodiscard]] bool near(std::size_t k) const noexcept { return near_[k] != 0; }
  // Marks this hop's tones and, given the engine's expected frequency (the track's prediction), the bins
  // where its lines may stand: within a resolution bin of a multiple of half of it (its half orders, orders
  // and comb); none without a prediction (NaN). At an idle of a few resolution bins that is most of the
  // band.
  void mark(double engine_hz) noexcept;
  // A learned tone: a mean from kFitLevel whose line has stayed put while the estimate moved (see learn()).
  [[nodiscard]] bool learned(std::size_t k) const noexcept { return tone_[k] >= kFitLevel && moved_[k] != 0; }
  // A reading this loud (normalised power) would make a tone within a few windows.
  [[nodiscard]] bool loud(double z) const noexcept;
  // Learns from this window's spectrum (power and noise floor per fine bin). The bins within two
  // resolution bins (a Hann main lobe's half-width) of the estimate's orders (`orders` x freq_hz; none when
  // freq_hz is NaN) and of its other integer multiples (an engine's comb; a bin there louder than the
  // fundamental is another line, and is learned) are left out while the estimate is probably the engine
  // (`on_track`); the orders of a `candidate` not yet confident are left out until they have persisted.
  void learn(const double* power, const double* noise, double freq_hz, std::span<const double> orders,
             bool on_track, bool candidate) noexcept;

 private:
  void local_maxima(const double* power, const double* noise, int radius) noexcept;

  int first_, last_, lobe_;
  double df_;
  double keep_;                  // per hop
  std::vector<double> tone_;     // mean normalised power
  std::vector<double> time_;     // share of the memory spent above kFitLevel
  std::vector<char> near_;       // within one resolution bin of a learned tone (this hop)
  std::vector<char> engine_;     // within one resolution bin of a multiple of half the engine (this hop)
  std::vector<double> lo_, hi_;  // the estimate's range (Hz) while the bin has stood as a line's peak
  std::vector<char> moved_;      // the estimate moved far while the bin stood as a line's peak (see learn())
  // This hop: the normalised power, and its maximum within two resolution bins (with the block maxima
  // that give it in one pass).
  std::vector<double> z_here_, z_around_, z_pre_, z_suf_;
};

}  // namespace gearpulse
