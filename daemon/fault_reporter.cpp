#include "daemon/fault_reporter.hpp"

#include <string_view>

#include <fmt/format.h>

#include "drivers/audio_front_end.hpp"

namespace gearpulse::daemon {

void FaultReporter::report(const std::string& key, spdlog::level::level_enum level, const std::string& text) {
  std::uint64_t suppressed = 0;
  if (!limiter_.allow(key, suppressed)) return;
  if (suppressed)
    spdlog::log(level, "{} (repeated {} times since the last report)", text, suppressed);
  else
    spdlog::log(level, "{}", text);
}

void FaultReporter::clear(const std::string& key, const std::string& text) {
  limiter_.reset(key);
  spdlog::info("{}", text);
}

void FaultReporter::audio(const AlsaCaptureStats& s, std::chrono::steady_clock::time_point at) noexcept {
  using Kind = FaultNote::Kind;
  using Say = StateFault::Say;
  std::uint64_t starts = 0;
  if (s.running) {
    if (const Say say = lost_.update(!s.streaming, at, starts); say == Say::kStart)
      post({Kind::kAudioLost, starts, s.last_error, 0.0, s.failed_step});
    else if (say == Say::kEnd)
      post({Kind::kAudioLostEnd, s.reopens});
  }
  if (const Say say = frozen_.update(s.frozen, at, starts); say == Say::kStart)
    post({Kind::kAudioFrozen, starts});
  else if (say == Say::kEnd)
    post({Kind::kAudioFrozenEnd});
  if (const Say say = stalled_.update(s.stalled, at, starts); say == Say::kStart)
    post({Kind::kAudioStalled, starts, 0, s.silent_s});
  else if (say == Say::kEnd)
    post({Kind::kAudioStalledEnd});
}

void FaultReporter::say_notes() noexcept {
  const std::lock_guard lock(saying_);
  while (const FaultNote* note = notes_.front()) {
    const FaultNote copy = *note;
    notes_.pop();
    try {
      say(copy);
    } catch (...) {  // no memory to format the line: the fault is in the status, the journal misses a line
    }
  }
  if (const std::uint64_t dropped = notes_.dropped(); dropped != dropped_said_) {
    try {
      report("faults-lost", spdlog::level::warn,
             fmt::format("faults: {} report(s) of the tracker thread lost (the main thread did not take "
                         "them in time)",
                         dropped - dropped_said_));
    } catch (...) {
    }
    dropped_said_ = dropped;
  }
}

void FaultReporter::say(const FaultNote& n) {
  const auto meanwhile = [&n](std::string_view what) {
    return n.count > 1 ? fmt::format(" ({} {} time(s) more since the last report)", what, n.count - 1)
                       : std::string();
  };
  switch (n.kind) {
    case FaultNote::Kind::kAudioLost:
      spdlog::warn(
          "audio: capture from {} interrupted (ALSA error {}: {}{}{}); the driver keeps reopening it; check "
          "that the sound card is plugged in and that audio.device names it (arecord -L){}",
          device_, n.error, alsa_error_text(n.error), n.step == AlsaStep::kNone ? "" : ", in ",
          to_string(n.step), meanwhile("lost"));
      break;
    case FaultNote::Kind::kAudioLostEnd:
      spdlog::info("audio: capture from {} resumed ({} reopen(s) so far)", device_, n.count);
      break;
    case FaultNote::Kind::kAudioFrozen:
      spdlog::warn(
          "audio: {} gives the same samples period after period (a source that has stopped, or digital "
          "silence); they are not used, and speed follows GPS (without a fix it coasts down from the last "
          "speed), until they change; check the wiring from the lighter socket to the card's input{}",
          device_, meanwhile("frozen"));
      break;
    case FaultNote::Kind::kAudioFrozenEnd:
      spdlog::info("audio: samples from {} change again", device_);
      break;
    case FaultNote::Kind::kAudioStalled:
      spdlog::warn(
          "audio: no samples from {} for {:.1f} s (the device is open but delivers nothing); speed follows "
          "GPS (without a fix it coasts down from the last speed) until they come again; check the card's "
          "cable and that no other program holds it{}",
          device_, n.seconds, meanwhile("stalled"));
      break;
    case FaultNote::Kind::kAudioStalledEnd:
      spdlog::info("audio: samples from {} come again", device_);
      break;
    case FaultNote::Kind::kAudioHole:
      report("audio-hole", spdlog::level::warn,
             fmt::format("audio: {} frames from {} lost before the ring (overrun, device restart or a "
                         "stalled source); tracking resumes after the hole",
                         n.count, device_));
      break;
    case FaultNote::Kind::kModelRejected:
      report("model", spdlog::level::err,
             fmt::format("synthesis: cannot use the new model ({} gears is more than it supports); keeping "
                         "the previous one",
                         n.count));
      break;
  }
}

}  // namespace gearpulse::daemon
