#pragma once
// Where audio frames come from: ALSA in the daemon, anything that fills the ring in tests.
// Frames flow through an SpscRing<float> (mono, the capture rate); the consumer counts the frames it has
// read (its "ring frame index", starting at 0) and asks the source for the CLOCK_MONOTONIC time of any
// frame it holds.
#include <cstdint>

namespace gearpulse {

class AudioSource {
 public:
  virtual ~AudioSource() = default;
  virtual void start() = 0;
  virtual void stop() = 0;
  [[nodiscard]] virtual unsigned rate() const noexcept = 0;  // frames per second after negotiation
  // CLOCK_MONOTONIC ns at which ring frame `index` was captured. False (and t_ns untouched) if no anchor
  // covers it: nothing captured yet, or the frame is so old that its anchor left the history. Frames
  // not pushed yet are extrapolated from the newest anchor.
  [[nodiscard]] virtual bool frame_time(std::uint64_t index, std::int64_t& t_ns) const noexcept = 0;
};

}  // namespace gearpulse
