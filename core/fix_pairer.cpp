#include "core/fix_pairer.hpp"

#include <cmath>

namespace gearpulse {

bool FixPairer::add(const PendingFix& fix) noexcept {
  if (count_ >= waiting_.size()) return false;
  waiting_[count_++] = fix;
  return true;
}

std::span<const PendingFix> FixPairer::take_due(double now, double served) noexcept {
  std::size_t due = 0;
  std::size_t keep = 0;
  for (std::size_t i = 0; i < count_; ++i) {
    const PendingFix f = waiting_[i];
    if (std::isfinite(served) && f.t <= served)
      due_[due++] = f;
    else if (now - f.t < max_wait_)
      waiting_[keep++] = f;
  }
  count_ = keep;
  return {due_.data(), due};
}

bool PairSpacing::take(double fix_time, double t) noexcept {
  // A clock that advanced pairs by its seconds; one that did not (or none), by receive time.
  const bool advanced = std::isfinite(fix_time) && fix_time != fix_time_;
  if (advanced ? std::floor(fix_time) == std::floor(fix_time_) : t - t_ < kMinGap) return false;
  fix_time_ = fix_time;
  t_ = t;
  return true;
}

std::optional<Sample> training_pair(const PendingFix& fix, double freq, double snr_db, bool tracked,
                                    double min_snr_db) noexcept {
  if (!tracked || !std::isfinite(freq) || !(snr_db >= min_snr_db)) return std::nullopt;
  return Sample{fix.wall, fix.speed, freq};
}

}  // namespace gearpulse
