#pragma once
// The audio front end of the live chain: the capture device and its ring, opened with backoff while it
// fails, read block by block with each block's CLOCK_MONOTONIC time and the holes before it (frames lost
// before the ring), and the device's state for status. The tracker thread owns it: open, read and close
// are called on that thread only; status() may be called from any.
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <string>

#include "core/spsc_ring.hpp"
#include "drivers/alsa_capture.hpp"

namespace gearpulse {

// One block read from the ring and where it sits on the sample clock.
struct AudioBlock {
  std::size_t frames = 0;  // read into the caller's buffer; 0 = the ring is empty
  bool timed = false;      // the capture could time its first frame (t0)
  bool first = false;      // the first timed block since the device was opened: the stream starts at t0
  double t0 = 0.0;         // CLOCK_MONOTONIC s of the block's first frame
  // Frames missing before this block, judged on the sample clock (0 = none): lost before the ring (an
  // overrun, a device restart, a stalled source) or periods the capture left out as repeats.
  std::uint64_t hole = 0;
  bool hole_lost = false;  // the hole is a loss, not repeated periods left out
};

// The device's state as status shows it.
struct AudioFrontEndStatus {
  bool open = false;       // a capture is open (its stats below); otherwise it is being retried
  AlsaCaptureStats stats;  // when open
  std::string error;       // the ALSA error of a device lost and being reopened, or why an open failed
  // While there is no audio (no capture open, or its device lost): the ALSA step that failed last
  // (kNone when what failed was no ALSA step: the stream refused, no thread), the attempts to open the
  // device since the audio went, and the wall-clock time (wall_now(), s) of the last one (0 none yet).
  // None, 0 and 0 while a device streams.
  AlsaStep failed_step = AlsaStep::kNone;
  std::uint64_t open_attempts = 0;
  double last_attempt = 0.0;
};

class AudioFrontEnd {
 public:
  // Called once a device is open, with its rate and description, before its capture starts: returns ""
  // or why the stream cannot be used at that rate (the open then counts as failed). May throw.
  using Prepare = std::function<std::string(unsigned rate, const std::string& describe)>;

  static constexpr std::chrono::milliseconds kFirstRetry{500};   // doubled after each failure ...
  static constexpr std::chrono::milliseconds kMaxRetry{10'000};  // ... up to this

  // `pushed` (optional, borrowed, must outlive this object) is signalled by the capture thread after every
  // push into the ring (AlsaCapture), so the reader can wait on it for the next block.
  AudioFrontEnd(AlsaCaptureConfig config, double ring_seconds, WakeEvent* pushed = nullptr);
  ~AudioFrontEnd();  // close()
  AudioFrontEnd(const AudioFrontEnd&) = delete;
  AudioFrontEnd& operator=(const AudioFrontEnd&) = delete;

  [[nodiscard]] bool is_open() const noexcept { return capture_ != nullptr; }
  // Whether an open is due: nothing open and the backoff since the last failure has passed.
  [[nodiscard]] bool open_due(std::chrono::steady_clock::time_point now) const noexcept;
  // When the backoff after the last failed open ends (the past before the first).
  [[nodiscard]] std::chrono::steady_clock::time_point next_open() const noexcept { return next_try_; }
  // Opens the device, its ring and its capture thread. On failure, false: error() says why, retry_delay()
  // how long until the next try (the delay then grows).
  bool open(std::chrono::steady_clock::time_point now, const Prepare& prepare);
  void close() noexcept;  // stops the capture thread; the device is closed

  // Reads the next block (at most into.size() frames) and times it.
  AudioBlock read(std::span<float> into) noexcept;
  // Frames wait in the ring (the reader's side: exact).
  [[nodiscard]] bool has_frames() const noexcept { return ring_ && !ring_->empty(); }

  [[nodiscard]] std::string error() const;
  [[nodiscard]] std::chrono::milliseconds retry_delay() const noexcept { return last_delay_; }
  [[nodiscard]] std::string describe() const;             // of the open device
  [[nodiscard]] unsigned rate() const noexcept;           // of the open device
  [[nodiscard]] unsigned period_frames() const noexcept;  // of the open device
  [[nodiscard]] std::uint64_t ring_dropped() const noexcept;
  [[nodiscard]] AlsaCaptureStats stats() const noexcept;  // of the open device
  [[nodiscard]] AudioFrontEndStatus status() const;

 private:
  AlsaCaptureConfig config_;
  double ring_seconds_;
  WakeEvent* pushed_signal_;
  std::chrono::steady_clock::time_point next_try_{};
  std::chrono::milliseconds backoff_ = kFirstRetry;
  std::chrono::milliseconds last_delay_ = kFirstRetry;

  mutable std::mutex mutex_;  // capture_ and ring_ as status() sees them, error_ and the three below
  std::unique_ptr<SpscRing<float>> ring_;
  std::unique_ptr<AlsaCapture> capture_;
  std::string error_;
  AlsaStep failed_step_ = AlsaStep::kNone;  // of the last failed open
  std::uint64_t open_attempts_ = 0;         // since the last open that succeeded
  double last_attempt_ = 0.0;               // wall_now() of the last failed open

  // The ring's read side.
  std::uint64_t read_frames_ = 0;  // ring frame index of the next frame to read
  double next_frame_t_ = 0.0;      // expected CLOCK_MONOTONIC s of that frame
  bool stream_started_ = false;
  std::uint64_t repeated_seen_ = 0;  // AlsaCaptureStats::repeated when the last hole was looked at
};

// libasound prints its own multi-line diagnostics to stderr on every failed open; the daemon logs one
// rate-limited line naming the device instead, and lets libasound's through only when `show` (at log
// level trace). Process-wide; called again on a change of level.
void show_alsa_library_errors(bool show) noexcept;
// "Input/output error" for -EIO: ALSA's text for an error code.
[[nodiscard]] std::string alsa_error_text(int code);

}  // namespace gearpulse
