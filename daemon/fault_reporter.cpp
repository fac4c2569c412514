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

void FaultReporter::audio(const AlsaCaptureStats& s, std::chrono::steady_clock::time_point at) {
  std::uint64_t starts = 0;
  const auto meanwhile = [&starts](std::string_view what) {
    return starts > 1 ? fmt::format(" ({} {} time(s) more since the last report)", what, starts - 1)
                      : std::string();
  };
  using Say = StateFault::Say;
  if (s.running) {
    const Say say = lost_.update(!s.streaming, at, starts);
    if (say == Say::kStart)
      spdlog::warn("audio: capture from {} interrupted (ALSA error {}: {}); the driver keeps reopening it{}",
                   device_, s.last_error, alsa_error_text(s.last_error), meanwhile("lost"));
    else if (say == Say::kEnd)
      spdlog::info("audio: capture from {} resumed ({} reopen(s) so far)", device_, s.reopens);
  }
  if (const Say say = frozen_.update(s.frozen, at, starts); say == Say::kStart)
    spdlog::warn(
        "audio: {} gives the same samples period after period (a source that has stopped, or digital "
        "silence); they are not used, and speed follows GPS (without a fix it coasts down from the last "
        "speed), until they change{}",
        device_, meanwhile("frozen"));
  else if (say == Say::kEnd)
    spdlog::info("audio: samples from {} change again", device_);
  if (const Say say = stalled_.update(s.stalled, at, starts); say == Say::kStart)
    spdlog::warn(
        "audio: no samples from {} for {:.1f} s (the device is open but delivers nothing); speed follows "
        "GPS (without a fix it coasts down from the last speed) until they come again{}",
        device_, s.silent_s, meanwhile("stalled"));
  else if (say == Say::kEnd)
    spdlog::info("audio: samples from {} come again", device_);
}

}  // namespace gearpulse::daemon
