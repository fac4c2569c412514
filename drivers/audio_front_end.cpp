#include "drivers/audio_front_end.hpp"

#include <alsa/asoundlib.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <stdexcept>

#include "drivers/clock.hpp"

namespace gearpulse {
namespace {

std::atomic<bool> alsa_errors_shown{false};

// libasound's diagnostics, written as its own handler writes them while they are shown, else dropped.
void alsa_error(const char* file, int line, const char* function, int err, const char* fmt, ...) {
  if (!alsa_errors_shown.load(std::memory_order_relaxed)) return;
  std::va_list args;
  va_start(args, fmt);
  std::fprintf(stderr, "ALSA lib %s:%i:(%s) ", file, line, function);
  std::vfprintf(stderr, fmt, args);
  va_end(args);
  if (err != 0) std::fprintf(stderr, ": %s", ::snd_strerror(err));
  std::fputc('\n', stderr);
}

}  // namespace

void show_alsa_library_errors(bool show) noexcept {
  alsa_errors_shown.store(show, std::memory_order_relaxed);
  // Installed once, before any thread opens a device; later calls (a reload) only flip the flag.
  static const bool installed = (snd_lib_error_set_handler(&alsa_error), true);
  (void)installed;
}

std::string alsa_error_text(int code) {
  return ::snd_strerror(code);
}

AudioFrontEnd::AudioFrontEnd(AlsaCaptureConfig config, double ring_seconds, WakeEvent* pushed)
    : config_(std::move(config)), ring_seconds_(ring_seconds), pushed_signal_(pushed) {}

AudioFrontEnd::~AudioFrontEnd() {
  close();
}

bool AudioFrontEnd::open_due(std::chrono::steady_clock::time_point now) const noexcept {
  return !capture_ && now >= next_try_;
}

bool AudioFrontEnd::open(std::chrono::steady_clock::time_point now, const Prepare& prepare) {
  const double attempt = wall_now();
  const auto fail = [&](std::string why, AlsaStep step = AlsaStep::kNone) {
    {
      std::lock_guard lock(mutex_);
      error_ = std::move(why);
      failed_step_ = step;
      ++open_attempts_;
      last_attempt_ = attempt;
    }
    last_delay_ = backoff_;
    next_try_ = now + backoff_;
    backoff_ = std::min(backoff_ * 2, kMaxRetry);
    return false;
  };
  std::unique_ptr<SpscRing<float>> ring;
  std::unique_ptr<AlsaCapture> capture;
  try {
    ring = std::make_unique<SpscRing<float>>(
        static_cast<std::size_t>(std::max(1.0, ring_seconds_ * config_.rate)));
    capture = std::make_unique<AlsaCapture>(config_, *ring, pushed_signal_);
  } catch (const AlsaOpenError& e) {
    return fail(e.what(), e.step());
  } catch (const std::exception& e) {
    return fail(e.what());
  }
  // What the caller prepares and the capture thread may not be had (memory, a thread limit): tried again
  // as a device that will not open is, never an exception out of the tracker's thread.
  try {
    if (std::string why = prepare(capture->rate(), capture->describe()); !why.empty())
      return fail(std::move(why));
    capture->start();
  } catch (const std::exception& e) {
    return fail("cannot start the capture from " + capture->describe() + ": " + e.what());
  }
  std::lock_guard lock(mutex_);
  ring_ = std::move(ring);
  capture_ = std::move(capture);
  error_.clear();
  failed_step_ = AlsaStep::kNone;
  open_attempts_ = 0;
  last_attempt_ = 0.0;
  backoff_ = kFirstRetry;
  read_frames_ = 0;
  stream_started_ = false;
  return true;
}

void AudioFrontEnd::close() noexcept {
  std::unique_ptr<AlsaCapture> capture;
  std::unique_ptr<SpscRing<float>> ring;
  {
    std::lock_guard lock(mutex_);
    capture = std::move(capture_);
    ring = std::move(ring_);
  }
  if (capture) capture->stop();
}

AudioBlock AudioFrontEnd::read(std::span<float> into) noexcept {
  AudioBlock block;
  if (!capture_) return block;
  const std::size_t n = ring_->read_bulk(into);
  if (n == 0) return block;
  block.frames = n;
  const double rate = capture_->rate();
  std::int64_t t_ns = 0;
  if (capture_->frame_time(read_frames_, t_ns)) {
    block.timed = true;
    block.t0 = t_ns * 1e-9;
    if (!stream_started_) {
      block.first = true;
      stream_started_ = true;
    } else {
      // Frames lost before the ring show as a forward jump of the sample clock (small differences are
      // drift corrections).
      const double gap_frames = (block.t0 - next_frame_t_) * rate;
      if (gap_frames > std::max(64.0, config_.period_frames / 2.0)) {
        block.hole = static_cast<std::uint64_t>(std::llround(gap_frames));
        // Repeated periods left out by the capture make a hole too; that one is no loss.
        const std::uint64_t repeated = capture_->stats().repeated;
        block.hole_lost = repeated == repeated_seen_;
        repeated_seen_ = repeated;
      }
    }
    next_frame_t_ = block.t0;
  }
  next_frame_t_ += n / rate;
  read_frames_ += n;
  return block;
}

std::string AudioFrontEnd::error() const {
  std::lock_guard lock(mutex_);
  return error_;
}

std::string AudioFrontEnd::describe() const {
  return capture_ ? capture_->describe() : std::string();
}

unsigned AudioFrontEnd::rate() const noexcept {
  return capture_ ? capture_->rate() : 0;
}

unsigned AudioFrontEnd::period_frames() const noexcept {
  return capture_ ? capture_->period_frames() : 0;
}

std::uint64_t AudioFrontEnd::ring_dropped() const noexcept {
  return ring_ ? ring_->dropped() : 0;
}

AlsaCaptureStats AudioFrontEnd::stats() const noexcept {
  return capture_ ? capture_->stats() : AlsaCaptureStats{};
}

AudioFrontEndStatus AudioFrontEnd::status() const {
  std::lock_guard lock(mutex_);
  AudioFrontEndStatus s;
  if (capture_) {
    s.open = true;
    s.stats = capture_->stats();
    if (s.stats.last_error != 0 && !s.stats.streaming)
      s.error =
          "ALSA error " + std::to_string(s.stats.last_error) + ": " + alsa_error_text(s.stats.last_error);
    if (!s.stats.streaming) {
      s.failed_step = s.stats.failed_step;
      s.open_attempts = s.stats.open_attempts;
      s.last_attempt = s.stats.last_attempt;
    }
  } else {
    s.error = error_;
    s.failed_step = failed_step_;
    s.open_attempts = open_attempts_;
    s.last_attempt = last_attempt_;
  }
  return s;
}

}  // namespace gearpulse
