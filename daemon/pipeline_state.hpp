#pragma once
// The states the pipeline reports for its output, its GPS and its audio, each with the word status
// gives it (docs/interfaces.md, `gearpulsectl status`) and the reading back of that word; and how a
// snapshot tells a fault counted recently (RecentGrowth).
#include <array>
#include <cstdint>
#include <optional>
#include <string_view>
#include <utility>

namespace gearpulse::daemon {

enum class OutputState {
  kOff,           // output none: pulses are counted, not emitted
  kOk,            // a reader takes the pulses (PTY) or the line is driven (GPIO)
  kNoReader,      // no process holds the PTY open
  kReaderBehind,  // pulses were dropped at a full reader queue within the last 5 s
  kWriteErrors,   // writes to the device failed within the last 5 s
  kError,         // the device would not open (retried)
};

enum class GpsState {
  kDisconnected,  // no connection to gpsd
  kNoFix,         // connected, no usable fix within gps.timeout
  kFix,
};

enum class AudioState {
  kStopped,     // the pipeline has not started
  kRunning,     // frames arrive and change
  kFrozen,      // the same period repeats (a stopped source, digital silence)
  kStalled,     // the device is open but delivers nothing
  kRecovering,  // the open capture lost its device and reopens it
  kRetrying,    // the capture could not be opened; tried again with backoff
};

namespace state_names {
using std::pair;
using std::string_view;
inline constexpr std::array kOutput = {pair{OutputState::kOff, string_view("off")},
                                       pair{OutputState::kOk, string_view("ok")},
                                       pair{OutputState::kNoReader, string_view("no-reader")},
                                       pair{OutputState::kReaderBehind, string_view("reader-behind")},
                                       pair{OutputState::kWriteErrors, string_view("write-errors")},
                                       pair{OutputState::kError, string_view("error")}};
inline constexpr std::array kGps = {pair{GpsState::kDisconnected, string_view("disconnected")},
                                    pair{GpsState::kNoFix, string_view("no-fix")},
                                    pair{GpsState::kFix, string_view("fix")}};
inline constexpr std::array kAudio = {pair{AudioState::kStopped, string_view("stopped")},
                                      pair{AudioState::kRunning, string_view("running")},
                                      pair{AudioState::kFrozen, string_view("frozen")},
                                      pair{AudioState::kStalled, string_view("stalled")},
                                      pair{AudioState::kRecovering, string_view("recovering")},
                                      pair{AudioState::kRetrying, string_view("retrying")}};

template <class Table, class E>
constexpr std::string_view name_in(const Table& table, E value) noexcept {
  for (const auto& [v, name] : table)
    if (v == value) return name;
  return "?";
}
template <class E, class Table>
constexpr std::optional<E> value_in(const Table& table, std::string_view name) noexcept {
  for (const auto& [v, n] : table)
    if (n == name) return v;
  return std::nullopt;
}
}  // namespace state_names

constexpr std::string_view to_string(OutputState s) noexcept {
  return state_names::name_in(state_names::kOutput, s);
}
constexpr std::string_view to_string(GpsState s) noexcept {
  return state_names::name_in(state_names::kGps, s);
}
constexpr std::string_view to_string(AudioState s) noexcept {
  return state_names::name_in(state_names::kAudio, s);
}

// The state a word of status names, or none.
template <class E>
constexpr std::optional<E> state_from_string(std::string_view name) noexcept;
template <>
constexpr std::optional<OutputState> state_from_string(std::string_view name) noexcept {
  return state_names::value_in<OutputState>(state_names::kOutput, name);
}
template <>
constexpr std::optional<GpsState> state_from_string(std::string_view name) noexcept {
  return state_names::value_in<GpsState>(state_names::kGps, name);
}
template <>
constexpr std::optional<AudioState> state_from_string(std::string_view name) noexcept {
  return state_names::value_in<AudioState>(state_names::kAudio, name);
}

// A count of a fault (pulses dropped, writes failed) and when a snapshot last saw it change: the fault is
// current while it did so within some time. A count that restarts (the device reopened) counts as a change.
// Not thread-safe: snapshots taken by several threads look under one lock.
class RecentGrowth {
 public:
  // `count` as seen at `now_ns`: true when it changed within `within_ns` of it.
  bool grew_recently(std::uint64_t count, std::int64_t now_ns, std::int64_t within_ns) noexcept {
    if (count != seen_) {
      seen_ = count;
      at_ns_ = now_ns;
    }
    return at_ns_ > 0 && now_ns - at_ns_ < within_ns;
  }

 private:
  std::uint64_t seen_ = 0;
  std::int64_t at_ns_ = 0;
};

}  // namespace gearpulse::daemon
