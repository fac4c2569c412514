#include "core/tone_map.hpp"

#include <algorithm>
#include <cmath>

namespace gearpulse {
namespace {

// Time over which a fixed tone is learned (s): far longer than any steady stretch of a moving engine
// the track does not cover.
constexpr double kMemoryS = 20.0;
// Share of the memory in which a bin near a candidate estimate's orders must have stood above kFitLevel
// before it is learned as a tone while the track is not confident, and that a bin read loud must have
// before the reading counts in full (about 2 s of a line present at every hop; see learn()).
constexpr double kPersist = 0.1;
// A bin this far below the strongest within two resolution bins of it is on a louder line's skirt, not a
// line of its own: a Hann window's first sidelobe is 31 dB down, its main lobe 15 dB down 1.5 bins out.
constexpr double kSkirt = 100.0;
constexpr double kQuickWindows = 5.0;  // a line is loud that would be a tone within this many windows
// A bin stands as a line's peak while its reading is within 3 dB of the strongest within two resolution
// bins: within 0.72 resolution bins of the line's centre (a Hann window's 3 dB bandwidth is 1.44 bins;
// Harris 1978, Table 1).
constexpr double kPeak = 2.0;
// How far the estimate must move (resolution bins) while a bin stands as a line's peak for that line to be
// a fixed tone: a line at order m of the engine moves m times as far as the estimate and stays within a
// peak's 1.44 bins until the estimate has moved 1.44 / m bins, 2.88 for the half order (the lowest the
// tracker fits).
constexpr double kMoved = 1.44 / 0.5;

}  // namespace

ToneMap::ToneMap(std::size_t bins, int first, int last, int lobe, double df_hz, double hop_s)
    : first_(first),
      last_(last),
      lobe_(lobe),
      df_(df_hz),
      keep_(std::exp(-hop_s / kMemoryS)),
      tone_(bins, 1.0),
      time_(bins, 0.0),
      near_(bins, 0),
      engine_(bins, 0),
      lo_(bins, INFINITY),
      hi_(bins, -INFINITY),
      moved_(bins, 0),
      z_here_(bins, 0.0),
      z_around_(bins, 0.0),
      z_pre_(bins, 0.0),
      z_suf_(bins, 0.0) {}

void ToneMap::reset() noexcept {
  std::fill(tone_.begin(), tone_.end(), 1.0);
  std::fill(time_.begin(), time_.end(), 0.0);
  std::fill(lo_.begin(), lo_.end(), INFINITY);
  std::fill(hi_.begin(), hi_.end(), -INFINITY);
  std::fill(moved_.begin(), moved_.end(), 0);
}

void ToneMap::mark(double engine_hz) noexcept {
  std::fill(near_.begin(), near_.end(), 0);
  const auto n = static_cast<int>(near_.size());
  std::fill(engine_.begin(), engine_.end(), 0);
  if (std::isfinite(engine_hz) && engine_hz > 0.0) {
    const double halves_per_bin = 2.0 * df_ / engine_hz;
    for (int k = 0; k < n; ++k) {
      const double m = std::max(1.0, std::round(k * halves_per_bin));
      engine_[static_cast<std::size_t>(k)] = std::abs(k * df_ - 0.5 * m * engine_hz) <= lobe_ * df_;
    }
  }
  for (int k = first_; k <= last_; ++k)
    if (learned(static_cast<std::size_t>(k)))
      for (int j = std::max(0, k - lobe_); j <= std::min(n - 1, k + lobe_); ++j)
        near_[static_cast<std::size_t>(j)] = 1;
}

bool ToneMap::loud(double z) const noexcept {
  return z * kQuickWindows * (1.0 - keep_) >= kFitLevel - 1.0;
}

void ToneMap::learn(const double* power, const double* noise, double freq_hz, std::span<const double> orders,
                    bool on_track, bool candidate) noexcept {
  local_maxima(power, noise, 2 * lobe_);
  // The engine's loudest line: the peak, within one resolution bin, of the estimate or of one of its orders.
  double loudest = INFINITY;
  if (on_track && std::isfinite(freq_hz) && freq_hz > 0.0) {
    const auto n = static_cast<int>(tone_.size());
    loudest = 0.0;
    const auto peak = [&](double hz) {
      const auto c = static_cast<int>(std::lround(hz / df_));
      for (int j = std::max(0, c - lobe_); j <= std::min(n - 1, c + lobe_); ++j)
        loudest = std::max(loudest, power[static_cast<std::size_t>(j)]);
    };
    peak(freq_hz);
    for (const double o : orders)
      peak(o * freq_hz);
  }
  for (int k = first_; k <= last_; ++k) {
    bool near = false;
    for (std::size_t o = 0; o < orders.size() && !near && std::isfinite(freq_hz); ++o)
      near = std::abs(k * df_ - orders[o] * freq_hz) <= 2.0 * lobe_ * df_;
    // Nor the engine's other harmonics while the track holds it: its ignition spikes give every multiple of
    // the fundamental (a comb), which at an idle stands still for seconds and, learned as tones, would
    // blank the orders of the engine's own next launch. Each line's whole main lobe (two resolution bins
    // either side) is its own: its shoulders, one to two bins out, stand within 20 dB of its peak (so the
    // skirt test below keeps them), and learned as tones they would blank a loud engine's orders
    // wherever they cross them.
    // A comb's multiple stands under the engine's lines (each multiple of a train of short pulses carries
    // about 2 A tau f of the fundamental's amplitude, -25 dB at 69 Hz on the generated scenes): a line louder
    // than the estimate and every one of its orders, at a multiple beyond the orders, is another line there
    // (a fan at four times the idle), and is learned. Not one louder than the estimate alone: with the track
    // at half the engine, the engine's own 2nd and 3rd harmonics stand at four and six times it.
    if (on_track && std::isfinite(freq_hz) && freq_hz > 0.0 && !near) {
      const double m = std::round(k * df_ / freq_hz);
      near = m >= 1.0 && std::abs(k * df_ - m * freq_hz) <= 2.0 * lobe_ * df_ && !(power[k] > loudest);
    }
    if (on_track && near) continue;
    const auto i = static_cast<std::size_t>(k);
    // The skirt of a loud line (30 dB and more over the noise spreads its leakage over several resolution
    // bins) moves with that line: it is not a tone of its own, and learned as one it blanked the band.
    const double z = z_here_[i] * kSkirt >= z_around_[i] ? z_here_[i] : std::min(z_here_[i], 1.0);
    time_[i] = keep_ * time_[i] + (z >= kFitLevel ? 1.0 - keep_ : 0.0);
    // The orders of a candidate not yet confident are learned only once they have persisted: a loud window
    // moves a bin's mean power past the fit level at once, and a clean engine line (40 dB over the noise)
    // not yet tracked at its first window was taken for a tone at its second and never acquired.
    if (candidate && near && time_[i] < kPersist) continue;
    // So is any loud reading: a loud line sweeping past (an order the estimate does not cover, an engine
    // not yet tracked) stays in a bin a few windows, a tone stays for good. Until it has persisted it may
    // raise the bin's mean to half the fit level (nothing is left out for it yet, and a tone that stays is
    // learned soon after); fainter readings are learned over many windows anyway.
    // Below 1 the mean says the floor stands over this bin's noise (see background()).
    const double next = keep_ * tone_[i] + (1.0 - keep_) * std::min(z, 1e3);
    tone_[i] = loud(z) && time_[i] < kPersist ? std::min(next, std::max(tone_[i], 0.5 * kFitLevel)) : next;
    // A line that stays put while the engine moves is a tone; one that stands in the bin only while the
    // estimate holds still may be the engine's (a half order, the alternator's whine, orders during an
    // unconfident spell), and 40 dB over the noise it raised the bin's mean past kFitLevel within a few
    // windows, marking a third of the band as tones that then blanked the engine's own orders.
    if (z >= kFitLevel && kPeak * z_here_[i] >= z_around_[i]) {
      if (std::isfinite(freq_hz)) {
        lo_[i] = std::min(lo_[i], freq_hz);
        hi_[i] = std::max(hi_[i], freq_hz);
        if (hi_[i] - lo_[i] > kMoved * lobe_ * df_) moved_[i] = 1;
      }
    } else {
      lo_[i] = INFINITY;
      hi_[i] = -INFINITY;
    }
    if (tone_[i] < kFitLevel) moved_[i] = 0;  // forgotten: must stay put through a move again
  }
}

// z_around_[k] = the largest normalised power within `radius` fine bins of k (first..last), in one pass
// over blocks of the window's width (van Herk / Gil-Werman): a window spans at most two blocks.
void ToneMap::local_maxima(const double* power, const double* noise, int radius) noexcept {
  const int n = last_ - first_ + 1;
  const int w = 2 * radius + 1;
  const auto at = [this](int j) { return static_cast<std::size_t>(first_ + j); };
  for (int j = 0; j < n; ++j)
    z_here_[at(j)] = power[at(j)] / noise[at(j)];
  for (int j = 0; j < n; ++j)
    z_pre_[at(j)] = j % w == 0 ? z_here_[at(j)] : std::max(z_pre_[at(j - 1)], z_here_[at(j)]);
  for (int j = n - 1; j >= 0; --j)
    z_suf_[at(j)] =
        j == n - 1 || (j + 1) % w == 0 ? z_here_[at(j)] : std::max(z_suf_[at(j + 1)], z_here_[at(j)]);
  for (int j = 0; j < n; ++j) {
    const int a = std::max(0, j - radius);
    const int b = std::min(n - 1, j + radius);
    // Within one block only when clipped by an end of the range: the part from its start or to its end.
    z_around_[at(j)] = a / w == b / w ? (a % w == 0 ? z_pre_[at(b)] : z_suf_[at(a)])
                                      : std::max(z_suf_[at(a)], z_pre_[at(b)]);
  }
}

}  // namespace gearpulse
