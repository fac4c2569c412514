#pragma once
// The live chain's faults in the journal: a fault is said when it happens, then at most once a minute
// with how often it happened meanwhile, and its end once. report() and clear() are thread-safe
// (LogLimiter). The tracker thread neither formats nor logs on its hops: it posts a FaultNote (a few
// numbers, into a lock-free ring) and the main thread says it (say_notes(), from Pipeline::service()), so
// these lines are stamped up to one turn of the main loop (a third of the watchdog interval, or 1 s)
// after the event. What the tracker thread says outside its hops (opening the capture) is logged at once.
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

#include <spdlog/spdlog.h>

#include "core/spsc_ring.hpp"
#include "daemon/log_limiter.hpp"
#include "drivers/alsa_capture.hpp"

namespace gearpulse::daemon {

// One thing the tracker thread has to say, in numbers only.
struct FaultNote {
  enum class Kind : std::uint8_t {
    kAudioLost,        // count: starts since the last said; error: the ALSA error; step: whose it was
    kAudioLostEnd,     // count: reopens so far
    kAudioFrozen,      // count: starts since the last said
    kAudioFrozenEnd,   //
    kAudioStalled,     // count: starts since the last said; seconds: silent for
    kAudioStalledEnd,  //
    kAudioHole,        // count: frames lost before the ring
    kModelRejected,    // count: the new model's gears
  };
  Kind kind = Kind::kAudioHole;
  std::uint64_t count = 0;
  int error = 0;
  double seconds = 0.0;
  AlsaStep step = AlsaStep::kNone;
};

class FaultReporter {
 public:
  explicit FaultReporter(std::string audio_device) : device_(std::move(audio_device)) {}

  // A fault under `key` (one key per kind of fault): logged now, or counted if it was logged less than a
  // minute ago.
  void report(const std::string& key, spdlog::level::level_enum level, const std::string& text);
  // The fault under `key` is over: `text` is logged, and its next occurrence is logged at once.
  void clear(const std::string& key, const std::string& text);

  // The tracker thread's: the open capture's faults (a lost device, reopened by the capture thread;
  // audio that freezes; audio that stalls), each posted when it starts and when it ends; a device that
  // comes and goes (a loose connector) at most once a minute.
  void audio(const AlsaCaptureStats& stats, std::chrono::steady_clock::time_point at) noexcept;
  // The tracker thread's: `note` is said at the main thread's next say_notes(). A note that does not fit
  // (the main thread held up for long) is counted, and the count is said.
  void post(const FaultNote& note) noexcept { (void)notes_.try_push(note); }
  // Logs the notes posted since the last call (any thread but the tracker's; one at a time). A note that
  // cannot be said (no memory to format it) is skipped: the daemon's loop goes on.
  void say_notes() noexcept;

 private:
  void say(const FaultNote& note);

  std::string device_;
  LogLimiter limiter_;
  StateFault lost_;  // lost_, frozen_, stalled_: the tracker thread's
  StateFault frozen_;
  StateFault stalled_;
  SpscRing<FaultNote> notes_{256};  // from the tracker thread to say_notes()
  std::mutex saying_;               // say_notes() is notes_'s one consumer at a time
  std::uint64_t dropped_said_ = 0;  // notes_.dropped() when said last (under saying_)
};

}  // namespace gearpulse::daemon
