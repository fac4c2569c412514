#pragma once
// Training pairs from live data: each GPS fix is paired with the engine frequency the tracker estimates
// on the audio window centred on the fix's instant (a pair is speed and frequency at one instant, paper
// eqs. (1)-(2)). A fix waits until the tracker's output covers its instant, at most `max_wait`; it is
// then paired if the estimate is good enough, else dropped. Time is an argument (CLOCK_MONOTONIC s in
// the daemon); the queue is fixed, so nothing allocates.
#include <array>
#include <cstddef>
#include <limits>
#include <optional>
#include <span>

#include "core/sample.hpp"

namespace gearpulse {

// A GPS fix waiting for the engine frequency of the audio window centred on it.
struct PendingFix {
  double t = 0.0;      // s of the fix (receive time - latency)
  double wall = 0.0;   // the same instant on the wall clock, the time the training store keeps
  double speed = 0.0;  // m/s
};

class FixPairer {
 public:
  static constexpr std::size_t kCapacity = 64;  // fixes waiting at once: 6 s of 10 Hz fixes

  explicit FixPairer(double max_wait_s) noexcept : max_wait_(max_wait_s) {}

  // Queues a fix; false when kCapacity fixes wait already (this one is not paired).
  bool add(const PendingFix& fix) noexcept;
  // The fixes at or before `served` (the newest instant the tracker can give a frequency for; NaN when
  // there is no tracker), in the order they came, however long they waited; of the others, those
  // `max_wait` or more older than `now` are given up, the rest go on waiting. The span is valid until
  // the next call.
  [[nodiscard]] std::span<const PendingFix> take_due(double now, double served) noexcept;
  [[nodiscard]] std::size_t waiting() const noexcept { return count_; }

 private:
  double max_wait_;
  std::array<PendingFix, kCapacity> waiting_{};
  std::size_t count_ = 0;
  std::array<PendingFix, kCapacity> due_{};
};

// At most one training pair a second: the first usable fix of each second of the receiver's clock is
// paired, the others of that second are not. Pairs a second apart are what the fit, the store's bounds and
// the learning schedule count (model.min_new_samples, replace_min_samples, learn_cluster_pairs and
// max_samples are seconds of driving at 1 Hz GPS), and what the fit may take as independent: the fixes of a
// 5 or 10 Hz receiver come out of its navigation filter, whose speed errors hold for about a second, and
// their frequencies from tracker windows (0.16 s at 0.1 s hops) of one smoothed track. Ten of them in a
// second are one second's evidence, not ten; counted as ten, a 10 Hz receiver would fit the young model
// after 4 s in a gear and replace a fitted model after 6 minutes of driving. A 1 Hz receiver's every fix
// is paired, as before. A receiver whose clock does not advance (none, or one standing still while the car
// moves) is paired once every kMinGap of receive time.
class PairSpacing {
 public:
  static constexpr double kMinGap = 0.9;  // s: a 1 Hz receiver's fixes, received with some jitter

  // Whether the usable fix of receiver time `fix_time` (UTC s, NaN = unknown), stamped `t` (s), is paired;
  // if so it is the last paired.
  [[nodiscard]] bool take(double fix_time, double t) noexcept;

 private:
  double fix_time_ = std::numeric_limits<double>::quiet_NaN();  // receiver time of the last pair
  double t_ = -std::numeric_limits<double>::infinity();         // its stamp
};

// The training pair of `fix` and the tracker's estimate at its instant: only a tracked, finite frequency
// at least `min_snr_db` above the noise makes one.
[[nodiscard]] std::optional<Sample> training_pair(const PendingFix& fix, double freq, double snr_db,
                                                  bool tracked, double min_snr_db) noexcept;

}  // namespace gearpulse
