#pragma once
// The engine-frequency tracker's input: a ring of the latest input frames and the anti-alias filter and
// decimator that reads windows out of it (a polyphase FIR, computed only for the decimated samples a
// window needs). The ring is written twice (at i and i + capacity) so that any span of up to capacity()
// frames is contiguous. Sized at construction; nothing allocates, locks or throws afterwards.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace gearpulse {

class DecimatingInput {
 public:
  // Input at fs_hz; the decimated signal holds every frequency up to top_hz faithfully.
  DecimatingInput(double fs_hz, double top_hz);
  // Makes the ring hold at least `frames` frames (at construction, before any write()).
  void reserve(std::size_t frames);

  [[nodiscard]] int factor() const noexcept { return decim_; }
  [[nodiscard]] double rate_hz() const noexcept { return fd_; }
  // Highest frequency the decimated signal represents faithfully.
  [[nodiscard]] double limit_hz() const noexcept { return limit_hz_; }
  [[nodiscard]] std::size_t taps() const noexcept { return fir_.size(); }
  [[nodiscard]] std::size_t capacity() const noexcept { return size_; }

  // Frames received, including skipped ones; the first frame after the latest hole.
  [[nodiscard]] std::uint64_t received() const noexcept { return n_in_; }
  [[nodiscard]] std::uint64_t valid_from() const noexcept { return valid_from_; }
  void clear() noexcept { n_in_ = valid_from_ = 0; }
  void write(float x) noexcept {
    if (!std::isfinite(x)) x = 0.0f;  // a glitch must not poison every window that sees it
    const std::size_t i = static_cast<std::size_t>(n_in_) & (size_ - 1);
    ring_[i] = x;
    ring_[i + size_] = x;
    ++n_in_;
  }
  // A hole of `frames` frames in the stream.
  void skip(std::uint64_t frames) noexcept {
    n_in_ += frames;
    valid_from_ = n_in_;
  }
  // The decimated sample whose filter starts at input frame `start` (taps() frames from there).
  [[nodiscard]] double sample(std::uint64_t start) const noexcept {
    const float* x = ring_.data() + (static_cast<std::size_t>(start) & (size_ - 1));
    double acc = 0.0;
    for (std::size_t k = 0; k < fir_.size(); ++k)
      acc += fir_[k] * static_cast<double>(x[k]);
    return acc;
  }

 private:
  int decim_ = 1;
  double fd_ = 0.0;
  double limit_hz_ = 0.0;
  std::vector<double> fir_;  // odd length, linear phase, unit DC gain
  std::size_t size_ = 1;
  std::vector<float> ring_;
  std::uint64_t n_in_ = 0;
  std::uint64_t valid_from_ = 0;
};

}  // namespace gearpulse
