// AlsaCapture (drivers/alsa_capture.hpp): its construction, its capture thread and the sample clock that
// stamps the frames, and its status; opening the PCM and naming its failures are alsa_pcm.cpp.
#include "drivers/alsa_capture.hpp"

#include <alsa/asoundlib.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <stdexcept>

#include "drivers/alsa_pcm.hpp"
#include "drivers/clock.hpp"
#include "drivers/realtime.hpp"

namespace gearpulse {
namespace {

// No frame for this long (or 4 periods, if longer) from an open device is a stall (AlsaCaptureStats).
constexpr double kStallS = 2.0;

std::size_t bytes_per_sample(PcmFormat f) noexcept {
  return f == PcmFormat::kS16 ? 2 : 4;
}

void sleep_ns(std::int64_t ns) noexcept {
  const timespec ts = to_timespec(monotonic_ns() + ns);
  while (::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

}  // namespace

AlsaCapture::AlsaCapture(AlsaCaptureConfig config, SpscRing<float>& ring, WakeEvent* pushed)
    : config_(std::move(config)), ring_(ring), pushed_signal_(pushed) {
  if (config_.period_frames == 0)
    throw std::runtime_error("ALSA capture '" + config_.device + "': period_frames must be positive");
  Negotiated got;
  OpenFailure failed;
  if (const int err = open_pcm(config_, pcm_, got, failed); err < 0)
    throw AlsaOpenError("ALSA capture '" + config_.device + "': " + failed.what + ": " + ::snd_strerror(err),
                        failed.step, err);
  rate_ = got.rate;
  channels_ = got.channels;
  format_ = got.format;
  period_frames_ = got.period;
  if (config_.channel >= static_cast<int>(channels_))
    throw std::runtime_error("ALSA capture '" + config_.device + "': channel " +
                             std::to_string(config_.channel) + " requested but the device gives " +
                             std::to_string(channels_));
  raw_.resize(static_cast<std::size_t>(period_frames_) * channels_ * bytes_per_sample(format_));
  previous_.resize(raw_.size());
  mono_.resize(period_frames_);
}

AlsaCapture::~AlsaCapture() {
  stop();
}

std::string AlsaCapture::describe() const {
  return config_.device + " " + std::to_string(rate_) + " Hz " + to_string(format_) + " " +
         std::to_string(channels_) + " ch, period " + std::to_string(period_frames_);
}

void AlsaCapture::start() {
  thread_.start([this] { run(); });
}

void AlsaCapture::stop() {
  thread_.stop();
}

AlsaCaptureStats AlsaCapture::stats() const noexcept {
  AlsaCaptureStats s;
  // First: the capture thread records a loss (its failure) and a reopen (its count) before it says it
  // streams or not (release), so what is read after this is at least as new as the state read here.
  s.streaming = streaming_.load(std::memory_order_acquire);
  s.frames = frames_.load(std::memory_order_relaxed);
  s.pushed = pushed_.load(std::memory_order_relaxed);
  s.dropped = dropped_.load(std::memory_order_relaxed);
  s.xruns = xruns_.load(std::memory_order_relaxed);
  s.suspends = suspends_.load(std::memory_order_relaxed);
  s.reopens = reopens_.load(std::memory_order_relaxed);
  s.clock_resets = clock_resets_.load(std::memory_order_relaxed);
  s.repeated = repeated_.load(std::memory_order_relaxed);
  s.frozen = frozen_.load(std::memory_order_relaxed);
  const AlsaFailure failure = AlsaFailure::from_word(failure_.load(std::memory_order_relaxed));
  s.last_error = failure.error;
  s.failed_step = failure.step;
  s.open_attempts = open_attempts_.load(std::memory_order_relaxed);
  s.last_attempt = last_attempt_.load(std::memory_order_relaxed);
  s.realtime_ok = thread_.realtime_ok();
  s.fifo = fifo_.load(std::memory_order_relaxed);
  s.memory_locked = thread_.memory_locked();
  s.realtime_refused = thread_.realtime_refused();
  s.running = thread_.running();
  if (const std::int64_t last = last_frames_ns_.load(std::memory_order_relaxed); s.streaming && last > 0) {
    const double period_s = static_cast<double>(period_frames_) / static_cast<double>(rate_);
    s.silent_s = std::max(0.0, static_cast<double>(monotonic_ns() - last) * 1e-9);
    s.stalled = s.silent_s > std::max(kStallS, 4.0 * period_s);
  }
  return s;
}

void AlsaCapture::note_failure(AlsaFailure failure) noexcept {
  failure_.store(failure.word(), std::memory_order_relaxed);
}

void AlsaCapture::publish_anchor(const Anchor& a) noexcept {
  std::uint64_t n = anchor_count_.load(std::memory_order_relaxed);
  // An anchor whose frame was never pushed (the ring was full) is replaced, not kept: a long stall must
  // not push the anchors of frames the consumer still holds out of the history.
  if (n > 0 && anchors_[(n - 1) % kAnchors].frame.load(std::memory_order_relaxed) == a.frame) --n;
  AnchorSlot& slot = anchors_[n % kAnchors];
  const std::uint32_t seq = slot.seq.load(std::memory_order_relaxed);
  // Seqlock with atomic fields only (no fences, so ThreadSanitizer understands it): the release stores
  // of the fields keep the odd sequence number before them, the reader's acquire loads keep its second
  // look at the sequence number after them.
  slot.seq.store(seq + 1, std::memory_order_relaxed);
  slot.frame.store(a.frame, std::memory_order_release);
  slot.t_ns.store(a.t_ns, std::memory_order_release);
  slot.ns_per_frame.store(a.ns_per_frame, std::memory_order_release);
  slot.seq.store(seq + 2, std::memory_order_release);
  anchor_count_.store(n + 1, std::memory_order_release);
}

bool AlsaCapture::frame_time(std::uint64_t index, std::int64_t& t_ns) const noexcept {
  const std::uint64_t n = anchor_count_.load(std::memory_order_acquire);
  const std::uint64_t oldest = n > kAnchors ? n - kAnchors : 0;
  for (std::uint64_t i = n; i-- > oldest;) {
    const AnchorSlot& slot = anchors_[i % kAnchors];
    Anchor a;
    for (;;) {  // seqlock read: retry while the capture thread is rewriting this slot
      const std::uint32_t s1 = slot.seq.load(std::memory_order_acquire);
      a.frame = slot.frame.load(std::memory_order_acquire);
      a.t_ns = slot.t_ns.load(std::memory_order_acquire);
      a.ns_per_frame = slot.ns_per_frame.load(std::memory_order_acquire);
      const std::uint32_t s2 = slot.seq.load(std::memory_order_relaxed);
      if (s1 == s2 && (s1 & 1u) == 0) break;
    }
    if (a.frame <= index) {
      t_ns = a.t_ns +
             static_cast<std::int64_t>(std::llround(static_cast<double>(index - a.frame) * a.ns_per_frame));
      return true;
    }
  }
  return false;
}

void AlsaCapture::run() noexcept {
  const RealtimeResult rt =
      thread_.enter_realtime({config_.realtime, config_.rt_priority, config_.lock_memory});
  fifo_.store(rt.fifo);
  snd_pcm_status_t* status_block = nullptr;
  if (::snd_pcm_status_malloc(&status_block) < 0) {
    note_failure({AlsaStep::kNone, -ENOMEM});
    return;
  }
  const std::unique_ptr<snd_pcm_status_t, decltype(&::snd_pcm_status_free)> status(status_block,
                                                                                   &::snd_pcm_status_free);
  thread_.set_running(true);

  const double nominal_npf = 1e9 / rate_;
  const double period_ns = nominal_npf * period_frames_;
  // Sample clock over the capture stream (every frame read from ALSA, frame c): t(c) = t0 + (c - c0) * npf.
  std::uint64_t c = 0;
  std::uint64_t c0 = 0;
  double t0 = 0.0;
  double npf = nominal_npf;
  std::uint64_t corrected_at = 0;
  bool have_clock = false;
  bool discontinuity = true;  // the next block starts a new stretch of the clock
  bool republish = true;      // the ring needs a new anchor before its next frame
  std::uint64_t ring_index = pushed_.load(std::memory_order_relaxed);  // continues across stop/start
  auto clock_at = [&](std::uint64_t frame) noexcept { return t0 + static_cast<double>(frame - c0) * npf; };

  // Capture time of the first frame of the block of n frames just read: ALSA's timestamp belongs to the
  // hardware position, which is `avail` frames beyond what has been read.
  auto measure = [&](snd_pcm_t* device, snd_pcm_sframes_t n) noexcept -> double {
    if (::snd_pcm_status(device, status.get()) == 0) {
      snd_htimestamp_t ts{};
      ::snd_pcm_status_get_htstamp(status.get(), &ts);
      if (ts.tv_sec != 0 || ts.tv_nsec != 0) {
        const double hw = static_cast<double>(ts.tv_sec) * 1e9 + static_cast<double>(ts.tv_nsec);
        return hw - static_cast<double>(::snd_pcm_status_get_avail(status.get()) + n) * nominal_npf;
      }
    }
    return static_cast<double>(monotonic_ns()) - static_cast<double>(n) * nominal_npf;
  };

  auto stopping = [this] { return thread_.stopping(); };
  // Sleeps in short steps so stop() is never kept waiting by a long backoff.
  auto pause = [&](std::int64_t ns) noexcept {
    const std::int64_t end = monotonic_ns() + ns;
    while (!stopping() && monotonic_ns() < end)
      sleep_ns(std::min<std::int64_t>(50'000'000, end - monotonic_ns()));
  };

  PcmHandle pcm = std::move(pcm_);  // the thread's while it runs
  // Prepares and starts the stream: the step that failed, noted (failure_), or none (error 0).
  auto restart = [&]() noexcept {
    AlsaFailure failure;
    if (const int err = ::snd_pcm_prepare(pcm.get()); err < 0)
      failure = {AlsaStep::kPrepare, err};
    else if (const int e = ::snd_pcm_start(pcm.get()); e < 0)
      failure = {AlsaStep::kStart, e};
    if (failure.error < 0) note_failure(failure);
    return failure;
  };
  // Recovery from `failure` as recovery_for() decides by its error; a failed restart or resume falls
  // through to a reopen.
  auto recover = [&](AlsaFailure failure) noexcept {
    const AlsaRecovery action = recovery_for(failure.error);
    if (action == AlsaRecovery::kRetry) return;  // a signal woke the wait: no frame was lost
    note_failure(failure);
    discontinuity = true;
    if (action == AlsaRecovery::kRestart) {
      xruns_.fetch_add(1, std::memory_order_relaxed);
      if (restart().error == 0) return;
    } else if (action == AlsaRecovery::kResume) {
      suspends_.fetch_add(1, std::memory_order_relaxed);
      int e;
      while ((e = ::snd_pcm_resume(pcm.get())) == -EAGAIN && !stopping())
        pause(100'000'000);
      if (e == 0 || restart().error == 0) return;
    }
    pcm.reset();
    open_attempts_.store(0, std::memory_order_relaxed);
    last_attempt_.store(0.0, std::memory_order_relaxed);
    streaming_.store(false, std::memory_order_release);
  };

  last_frames_ns_.store(monotonic_ns(), std::memory_order_relaxed);
  streaming_.store(pcm != nullptr, std::memory_order_relaxed);
  if (pcm) {
    if (const AlsaFailure failure = restart(); failure.error < 0) recover(failure);
  }
  std::int64_t backoff = std::chrono::duration_cast<std::chrono::nanoseconds>(config_.reopen_min).count();
  const std::int64_t backoff_max =
      std::chrono::duration_cast<std::chrono::nanoseconds>(config_.reopen_max).count();
  const int wait_ms = static_cast<int>(std::max<std::int64_t>(1, config_.wait_timeout.count()));
  const std::size_t sample_bytes = bytes_per_sample(format_);
  std::size_t previous_frames = 0;  // frames in previous_ (0: none yet)
  std::size_t repeat_run = 0;       // frames repeated in a row
  // A source that delivers faster than real time (a file, or a FIFO whose writer has gone: the file
  // plugin then hands back its last period at once) would spin this thread. A sound card never runs
  // ahead of the clock, so holding the stream to at most a second ahead of real time only touches those.
  auto hold_to_clock = [&]() noexcept {
    const double ahead = clock_at(c) - static_cast<double>(monotonic_ns());
    if (ahead > 1e9) pause(static_cast<std::int64_t>(ahead - 0.5e9));
  };

  while (!stopping()) {
    if (!pcm) {
      // A lost device is reopened under the normal policy (AlsaCaptureStats::fifo).
      if (fifo_.load(std::memory_order_relaxed) && set_fifo(false, 0))
        fifo_.store(false, std::memory_order_relaxed);
      pause(backoff);
      if (stopping()) break;
      Negotiated got;
      OpenFailure failed;
      PcmHandle fresh;
      open_attempts_.fetch_add(1, std::memory_order_relaxed);
      last_attempt_.store(wall_now(), std::memory_order_relaxed);
      const int err = open_pcm(config_, fresh, got, failed);
      const bool changed = err == 0 && (got.rate != rate_ || got.channels != channels_ ||
                                        got.format != format_ || got.period != period_frames_);
      if (err < 0 || changed) {
        note_failure(changed ? AlsaFailure{AlsaStep::kParamsChanged, -EINVAL}
                             : AlsaFailure{failed.step, err});
        backoff = std::min(backoff * 2, backoff_max);
        continue;
      }
      pcm = std::move(fresh);
      if (rt.fifo) fifo_.store(set_fifo(true, config_.rt_priority), std::memory_order_relaxed);
      last_frames_ns_.store(monotonic_ns(), std::memory_order_relaxed);
      // Counted before it says it streams: a look that finds it streaming again finds the reopen counted.
      reopens_.fetch_add(1, std::memory_order_relaxed);
      streaming_.store(true, std::memory_order_release);
      backoff = std::chrono::duration_cast<std::chrono::nanoseconds>(config_.reopen_min).count();
      if (const int e = ::snd_pcm_start(pcm.get()); e < 0) recover({AlsaStep::kStart, e});
      continue;
    }
    const int ready = ::snd_pcm_wait(pcm.get(), wait_ms);
    if (ready < 0) {
      recover({AlsaStep::kWait, ready});
      continue;
    }
    if (ready == 0) continue;  // timeout: look at stop_ again
    const snd_pcm_sframes_t n = ::snd_pcm_readi(pcm.get(), raw_.data(), period_frames_);
    if (n == -EAGAIN || n == 0) {
      pause(static_cast<std::int64_t>(period_ns / 4));  // ready but nothing to read: never spin
      continue;
    }
    if (n < 0) {
      recover({AlsaStep::kRead, static_cast<int>(n)});
      continue;
    }
    const double measured = measure(pcm.get(), n);
    frames_.fetch_add(static_cast<std::uint64_t>(n), std::memory_order_relaxed);
    last_frames_ns_.store(monotonic_ns(), std::memory_order_relaxed);
    const std::size_t frames = static_cast<std::size_t>(n);

    // A period identical to the one before is a stopped source or digital silence (AlsaCaptureStats::
    // frozen): not pushed, so the tracker sees no audio rather than an engine frozen at one speed. The
    // sample clock runs on; the next period pushed gets a fresh anchor.
    const std::size_t bytes = frames * channels_ * sample_bytes;
    const bool repeat = frames == previous_frames && std::memcmp(raw_.data(), previous_.data(), bytes) == 0;
    // A copy, not a swap: the file plugin leaves the buffer untouched when its input has ended, so the
    // stale period is whatever the buffer last held.
    std::memcpy(previous_.data(), raw_.data(), bytes);
    previous_frames = frames;
    // Frozen once half a second has repeated (a gated input's odd pair of silent periods is not).
    repeat_run = repeat ? repeat_run + frames : 0;
    frozen_.store(repeat_run >= rate_ / 2, std::memory_order_relaxed);
    if (repeat) {
      repeated_.fetch_add(frames, std::memory_order_relaxed);
      discontinuity = true;
      c += frames;
      hold_to_clock();
      continue;
    }

    // Convert to float mono.
    for (std::size_t i = 0; i < frames; ++i) {
      float acc = 0.0f;
      for (unsigned ch = 0; ch < channels_; ++ch) {
        if (config_.channel >= 0 && static_cast<int>(ch) != config_.channel) continue;
        const std::byte* p = raw_.data() + (i * channels_ + ch) * sample_bytes;
        float v;
        if (format_ == PcmFormat::kS16) {
          std::int16_t s;
          std::memcpy(&s, p, 2);
          v = static_cast<float>(s) / 32768.0f;
        } else if (format_ == PcmFormat::kS32) {
          std::int32_t s;
          std::memcpy(&s, p, 4);
          v = static_cast<float>(static_cast<double>(s) / 2147483648.0);
        } else {
          std::memcpy(&v, p, 4);
        }
        acc += v;
      }
      mono_[i] = config_.channel >= 0 ? acc : acc / static_cast<float>(channels_);
    }

    // Sample clock: anchor on a discontinuity, otherwise slew slowly towards ALSA's timestamps.
    if (!have_clock || discontinuity) {
      // Never back in time: frames after a hole were captured after those before it.
      const double t = have_clock ? std::max(measured, clock_at(c)) : measured;
      if (have_clock) clock_resets_.fetch_add(1, std::memory_order_relaxed);
      c0 = c;
      t0 = t;
      corrected_at = c;
      have_clock = true;
      discontinuity = false;
      republish = true;
    } else if (c - corrected_at >= rate_ / 4) {
      const double err = measured - clock_at(c);
      const double max_err = std::max(100e6, 4 * period_ns);  // beyond: frames were lost, not late
      if (err > max_err) {  // frames went missing without an xrun report: jump forward
        t0 = measured;
        c0 = c;
        clock_resets_.fetch_add(1, std::memory_order_relaxed);
        republish = true;
      } else if (err >= -max_err) {
        // Rate from the error accumulated since the last correction, offset by a fraction of it; a
        // backward step stays under one frame so frame times remain increasing across anchors.
        const double now_t = clock_at(c);  // on the old rate: the anchor must continue the old line
        const double step = std::clamp(err / 8.0, -0.5 * npf, period_ns / 8.0);
        npf += err / static_cast<double>(c - corrected_at) / 16.0;
        npf = std::clamp(npf, nominal_npf * (1 - 500e-6), nominal_npf * (1 + 500e-6));
        t0 = now_t + step;
        c0 = c;
        republish = true;
      }
      // err < -max_err: frames arrive faster than real time (a file source); keep the sample clock.
      corrected_at = c;
    }
    if (republish) {
      publish_anchor({ring_index, static_cast<std::int64_t>(std::llround(clock_at(c))), npf});
    }
    const std::size_t pushed = ring_.try_push_bulk(std::span<const float>(mono_.data(), frames));
    // After the push (its release store of the ring's write index): a consumer whose wait took this
    // signal finds the frames.
    if (pushed > 0 && pushed_signal_) pushed_signal_->signal();
    ring_index += pushed;
    pushed_.store(ring_index, std::memory_order_relaxed);
    // Frames the ring had no room for are the block's tail: the next frame pushed needs a fresh anchor.
    republish = pushed < frames;
    if (pushed < frames) dropped_.fetch_add(frames - pushed, std::memory_order_relaxed);
    c += frames;
    hold_to_clock();
  }
  if (pcm) ::snd_pcm_drop(pcm.get());
  pcm_ = std::move(pcm);
  streaming_.store(false);
  thread_.set_running(false);
}

}  // namespace gearpulse
