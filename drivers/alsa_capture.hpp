#pragma once
// ALSA capture into the SPSC ring, with sample-clock timestamps.
//
// A capture thread reads periods (non-blocking PCM, snd_pcm_wait with a timeout so stop() is prompt and
// the thread never spins; a source faster than real time, such as a file, is held to at most a second
// ahead of the clock), converts S16/S32/FLOAT interleaved frames to float mono (one chosen channel or
// the mean of all) and pushes them with try_push_bulk. Recovery follows the PCM state as PipeWire does:
// -EPIPE (XRUN) and -ESTRPIPE (SUSPENDED: resume, else prepare) are handled separately, then the stream
// is prepared and restarted; -ENODEV and other fatal errors close the PCM and reopen it with backoff.
//
// Timestamps: the ring stream (what the consumer reads, frame 0 = first frame pushed) is mapped to
// CLOCK_MONOTONIC by anchors {ring frame, time, ns per frame}. The first anchor comes from the stream
// start; ALSA's status timestamps (htstamp minus the frames still waiting in the buffer) then correct
// offset and rate slowly. Frames lost before the ring — an XRUN, a restart, or frames dropped because
// the ring was full — do not exist in the ring stream: the next frame that is pushed gets a new anchor
// at its true capture time, so timestamps jump forward across a hole and are monotonic throughout. The
// anchors live in a small seqlock history so the consumer finds the one for any frame it still holds.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/spsc_ring.hpp"
#include "drivers/device_thread.hpp"
#include "drivers/wake_event.hpp"

struct _snd_pcm;  // ALSA's snd_pcm_t, kept opaque so users need no ALSA headers

namespace gearpulse {

// Owns an open ALSA PCM: snd_pcm_close when the handle goes.
struct PcmClose {
  void operator()(_snd_pcm* pcm) const noexcept;
};
using PcmHandle = std::unique_ptr<_snd_pcm, PcmClose>;

// The encoding of one audio sample on the capture device (ALSA's S16_LE, S32_LE and FLOAT_LE).
enum class PcmFormat : std::uint8_t { kS16, kS32, kFloat };

[[nodiscard]] const char* to_string(PcmFormat format) noexcept;

// What the capture does about a negative ALSA return code. By the error, as PipeWire's alsa_recover
// does: an overrun and a suspend are told apart, a signal is no fault at all, and anything else means
// the device is gone or broken.
enum class AlsaRecovery : std::uint8_t {
  kRetry,    // -EINTR, -EAGAIN: nothing is wrong with the stream; wait again
  kRestart,  // -EPIPE (XRUN): frames were lost; prepare and start again
  kResume,   // -ESTRPIPE (SUSPENDED): resume, or prepare and start if the device cannot
  kReopen,   // -ENODEV and anything else: close the PCM and reopen it with backoff
};

[[nodiscard]] AlsaRecovery recovery_for(int alsa_error) noexcept;
[[nodiscard]] const char* to_string(AlsaRecovery recovery) noexcept;

// The step of opening or running the capture that failed with an ALSA error (AlsaCaptureStats), so
// status can say where a lost device fails without the capture thread building a string.
enum class AlsaStep : std::uint8_t {
  kNone,           // nothing has failed
  kOpen,           // snd_pcm_open: no such device, busy, no permission
  kHwParams,       // the hardware parameters: access, format, channels, rate, period or buffer refused
  kSwParams,       // the software parameters
  kParamsChanged,  // reopened, but the device now gives another rate, format, channel count or period
  kPrepare,        // snd_pcm_prepare
  kStart,          // snd_pcm_start
  kWait,           // snd_pcm_wait
  kRead,           // snd_pcm_readi
};

// "open", "hw-params", "sw-params", "params-changed", "prepare", "start", "wait", "read"; "" for kNone.
[[nodiscard]] const char* to_string(AlsaStep step) noexcept;

// A failed ALSA call: its step and the negative error code it returned (kNone and 0: nothing failed).
struct AlsaFailure {
  AlsaStep step = AlsaStep::kNone;
  int error = 0;

  // In one word, so that one atomic holds a failure whole: the error's 32 bits low, the step above them.
  [[nodiscard]] std::uint64_t word() const noexcept;
  [[nodiscard]] static AlsaFailure from_word(std::uint64_t word) noexcept;
};

// The capture could not be opened: what() is the one-line message AlsaCapture's constructor documents,
// step() and error() (the negative ALSA code) say where and why.
class AlsaOpenError : public std::runtime_error {
 public:
  AlsaOpenError(const std::string& what, AlsaStep step, int error)
      : std::runtime_error(what), step_(step), error_(error) {}
  [[nodiscard]] AlsaStep step() const noexcept { return step_; }
  [[nodiscard]] int error() const noexcept { return error_; }

 private:
  AlsaStep step_;
  int error_;
};

struct AlsaCaptureConfig {
  std::string device = "default";
  unsigned rate = 48000;               // requested; the nearest the device offers is used
  unsigned channels = 1;               // requested; the nearest the device offers is used
  PcmFormat format = PcmFormat::kS16;  // preferred; the others are tried if it is refused
  int channel = -1;                    // channel to keep, -1 = mean of all channels
  unsigned period_frames = 1024;
  unsigned periods = 4;   // buffer = periods * period_frames
  bool realtime = false;  // SCHED_FIFO for the capture thread (failure reported)
  int rt_priority = 70;
  bool lock_memory = false;                     // mlockall (failure reported)
  std::chrono::milliseconds wait_timeout{200};  // snd_pcm_wait bound: how late stop() can be
  std::chrono::milliseconds reopen_min{100};    // backoff after a lost device, doubled up to reopen_max
  std::chrono::milliseconds reopen_max{2000};
};

struct AlsaCaptureStats {
  std::uint64_t frames = 0;        // frames read from ALSA
  std::uint64_t pushed = 0;        // frames pushed into the ring (= ring frame index of the next frame)
  std::uint64_t dropped = 0;       // frames the ring had no room for
  std::uint64_t xruns = 0;         // -EPIPE recoveries
  std::uint64_t suspends = 0;      // -ESTRPIPE recoveries
  std::uint64_t reopens = 0;       // successful reopens after a lost device
  std::uint64_t clock_resets = 0;  // anchors placed after a discontinuity or a large clock error
  std::uint64_t repeated = 0;      // frames of periods identical to the period before (not pushed)
  int last_error = 0;              // last negative ALSA error code seen, 0 if none
  AlsaStep failed_step = AlsaStep::kNone;  // the step that returned last_error
  // Attempts to reopen the device since it was last lost, and the wall-clock time (wall_now(), s) of the
  // last of them (0 if none yet).
  std::uint64_t open_attempts = 0;
  double last_attempt = 0.0;
  bool realtime_ok = false;  // SCHED_FIFO granted at start
  // The capture thread runs under SCHED_FIFO now: not while it reopens a lost device, since opening one
  // (ALSA parses its configuration and allocates) is no real-time work, and at the FIFO priority it would
  // hold the tracker off its core at every attempt.
  bool fifo = false;
  bool memory_locked = false;
  bool realtime_refused = false;  // SCHED_FIFO or the memory lock asked for at start was refused
  bool running = false;           // the capture thread runs
  bool streaming = false;  // ... and the device is open and capturing (false while it is lost and reopened)
  // The last half second of periods each repeated the one before, bit for bit: a source that has
  // stopped (the file plugin hands back its buffer unchanged once its input ends) or digital silence
  // (a muted input). A live analogue input never repeats a period exactly, so a repeated period carries
  // nothing and is not pushed (from the first one; `repeated` counts them).
  bool frozen = false;
  // The device is open but has delivered no frame for 2 s or 4 periods, whichever is longer (a card whose
  // pointer stopped, a source that holds its stream open and sends nothing); `silent_s` says how long.
  bool stalled = false;
  double silent_s = 0.0;
};

class AlsaCapture final {
 public:
  // Opens and configures the PCM now, so a bad name or a refused format fails here with a one-line
  // AlsaOpenError ("ALSA capture 'foo': cannot open: No such file or directory"; other faults of the
  // configuration are a std::runtime_error). `ring` is borrowed and must outlive this object; this object
  // is its only producer. `pushed` (optional, borrowed) is signalled after every push into the ring, so
  // the consumer can wait for frames instead of polling (WakeEvent: a wake-up is never lost).
  AlsaCapture(AlsaCaptureConfig config, SpscRing<float>& ring, WakeEvent* pushed = nullptr);
  ~AlsaCapture();  // stop()
  AlsaCapture(const AlsaCapture&) = delete;
  AlsaCapture& operator=(const AlsaCapture&) = delete;

  void start();  // starts the capture thread (idempotent)
  void stop();   // joins within about wait_timeout

  [[nodiscard]] unsigned rate() const noexcept { return rate_; }  // frames per second after negotiation
  [[nodiscard]] unsigned channels() const noexcept { return channels_; }
  [[nodiscard]] PcmFormat format() const noexcept { return format_; }
  [[nodiscard]] unsigned period_frames() const noexcept { return period_frames_; }
  // CLOCK_MONOTONIC ns at which ring frame `index` (the consumer's count of frames read, from 0) was
  // captured. False (and t_ns untouched) if no anchor covers it: nothing captured yet, or the frame is so
  // old that its anchor left the history. Frames not pushed yet are extrapolated from the newest anchor.
  [[nodiscard]] bool frame_time(std::uint64_t index, std::int64_t& t_ns) const noexcept;
  [[nodiscard]] AlsaCaptureStats stats() const noexcept;
  [[nodiscard]] std::string describe() const;  // "hw:0 48000 Hz S16 2 ch, period 1024"

  struct Anchor {
    std::uint64_t frame = 0;    // ring frame index
    std::int64_t t_ns = 0;      // CLOCK_MONOTONIC of that frame
    double ns_per_frame = 0.0;  // local rate of the sample clock
  };

 private:
  void run() noexcept;
  void publish_anchor(const Anchor& anchor) noexcept;
  void note_failure(AlsaFailure failure) noexcept;  // failure_

  static constexpr std::size_t kAnchors = 64;
  struct alignas(kCacheLine) AnchorSlot {
    std::atomic<std::uint32_t> seq{0};
    std::atomic<std::uint64_t> frame{0};
    std::atomic<std::int64_t> t_ns{0};
    std::atomic<double> ns_per_frame{0.0};
  };

  AlsaCaptureConfig config_;
  SpscRing<float>& ring_;
  WakeEvent* pushed_signal_;
  PcmHandle pcm_;  // the device while the capture thread does not run (it holds it meanwhile)
  unsigned rate_ = 0;
  unsigned channels_ = 0;
  PcmFormat format_ = PcmFormat::kS16;
  unsigned period_frames_ = 0;
  std::vector<std::byte> raw_;       // one period as read
  std::vector<std::byte> previous_;  // a copy of the period read before it
  std::vector<float> mono_;          // one period converted
  std::atomic<bool> streaming_{false};
  AnchorSlot anchors_[kAnchors];
  std::atomic<std::uint64_t> anchor_count_{0};
  std::atomic<std::uint64_t> frames_{0}, pushed_{0}, dropped_{0}, xruns_{0}, suspends_{0}, reopens_{0},
      clock_resets_{0}, repeated_{0};
  // The last failure (AlsaFailure::word()), one word written once per failure, so stats() never pairs one
  // failure's error with another's step.
  std::atomic<std::uint64_t> failure_{0};
  static_assert(std::atomic<std::uint64_t>::is_always_lock_free);
  std::atomic<std::uint64_t> open_attempts_{0};
  std::atomic<double> last_attempt_{0.0};
  std::atomic<bool> fifo_{false}, frozen_{false};
  std::atomic<std::int64_t> last_frames_ns_{0};  // monotonic time of the last frames read (or of the start)
  DeviceThread thread_;                          // last: stopped before the members it uses go
};

}  // namespace gearpulse
