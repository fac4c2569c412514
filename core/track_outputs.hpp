#pragma once
// The engine-frequency tracker's outputs: a queue the caller pops in time order (when nobody pops, the
// oldest are dropped and counted) and the history of the latest hops that at() and nearest() look back
// on. Fixed rings sized at construction; nothing allocates, locks or throws afterwards.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/sliding_dft_tracker.hpp"

namespace gearpulse {

class TrackOutputs {
 public:
  TrackOutputs(std::size_t queue_capacity, std::size_t history_capacity)
      : queue_(queue_capacity), history_(history_capacity) {}

  // Forgets every output (the count of dropped ones stays).
  void clear() noexcept { q_head_ = q_size_ = h_head_ = h_size_ = 0; }

  void emit(const TrackPoint& p) noexcept {
    if (q_size_ == queue_.size()) {
      q_head_ = (q_head_ + 1) % queue_.size();
      --q_size_;
      ++dropped_;
    }
    queue_[(q_head_ + q_size_) % queue_.size()] = p;
    ++q_size_;
    history_[(h_head_ + h_size_) % history_.size()] = p;
    if (h_size_ == history_.size())
      h_head_ = (h_head_ + 1) % history_.size();
    else
      ++h_size_;
  }

  // The hop of time p.t in the history, if it is still there, takes p's confidence (decided later).
  void revise(const TrackPoint& p) noexcept {
    for (std::size_t k = h_size_; k-- > 0;) {
      TrackPoint& h = history_[(h_head_ + k) % history_.size()];
      if (h.t < p.t) return;
      if (h.t == p.t) {
        h.confidence = p.confidence;
        h.tracked = p.tracked;
        return;
      }
    }
  }

  bool pop(TrackPoint& out) noexcept {
    if (q_size_ == 0) return false;
    out = queue_[q_head_];
    q_head_ = (q_head_ + 1) % queue_.size();
    --q_size_;
    return true;
  }

  // The hops held in the history, oldest first: recent(0) .. recent(held() - 1).
  [[nodiscard]] std::size_t held() const noexcept { return h_size_; }
  [[nodiscard]] const TrackPoint& recent(std::size_t k) const noexcept {
    return history_[(h_head_ + k) % history_.size()];
  }

  [[nodiscard]] std::size_t queue_capacity() const noexcept { return queue_.size(); }
  [[nodiscard]] std::size_t history_capacity() const noexcept { return history_.size(); }
  [[nodiscard]] std::uint64_t dropped() const noexcept { return dropped_; }

 private:
  std::vector<TrackPoint> queue_;
  std::size_t q_head_ = 0, q_size_ = 0;
  std::vector<TrackPoint> history_;
  std::size_t h_head_ = 0, h_size_ = 0;
  std::uint64_t dropped_ = 0;
};

}  // namespace gearpulse
