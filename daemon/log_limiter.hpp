#pragma once
// Repeated faults (gpsd down, a device gone) must not flood the journal at 2 a.m.: the first
// occurrence is logged, then at most one line per interval saying how often it happened meanwhile.
#include <chrono>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>

namespace gearpulse::daemon {

class LogLimiter {
 public:
  explicit LogLimiter(std::chrono::seconds interval = std::chrono::seconds(60)) : interval_(interval) {}

  // True if a line for `key` should be written now; `suppressed` is set to the number of occurrences
  // swallowed since the last line.
  bool allow(const std::string& key, std::uint64_t& suppressed) {
    std::lock_guard lock(mutex_);
    const auto now = std::chrono::steady_clock::now();
    auto& e = entries_[key];
    if (e.logged && now - e.last < interval_) {
      ++e.suppressed;
      return false;
    }
    suppressed = e.suppressed;
    e = Entry{now, 0, true};
    return true;
  }
  // The fault is over: the next occurrence is logged at once.
  void reset(const std::string& key) {
    std::lock_guard lock(mutex_);
    entries_.erase(key);
  }

 private:
  struct Entry {
    std::chrono::steady_clock::time_point last{};
    std::uint64_t suppressed = 0;
    bool logged = false;
  };
  std::chrono::seconds interval_;
  std::mutex mutex_;
  std::map<std::string, Entry> entries_;
};

// A fault that persists across attempts (a save failing every few minutes on a full or read-only disk)
// is said when it starts, when it changes and when it ends, not at every attempt. Not thread-safe: one
// owner, or the caller's lock.
class FaultSpell {
 public:
  // An attempt failed with `what`: true when it should be said (the spell's first, or unlike the last).
  bool failed(std::string what) {
    const bool news = what != what_;
    what_ = std::move(what);
    return news;
  }
  // An attempt worked: true when that ends a spell (say it works again).
  bool succeeded() noexcept {
    const bool ended = !what_.empty();
    what_.clear();
    return ended;
  }
  [[nodiscard]] bool failing() const noexcept { return !what_.empty(); }
  [[nodiscard]] const std::string& what() const noexcept { return what_; }

 private:
  std::string what_;
};

// A fault that is a state of a device (lost, frozen, stalled), which a loose connector can make come and
// go many times a minute: its start is said at once, then at most once per interval (with how often it
// started meanwhile); a start held back is said once the interval is over if the state still holds; its
// end is said only when its start was. A state that flaps thus writes two lines a minute, not two per
// flap. Not thread-safe: one owner.
class StateFault {
 public:
  using Clock = std::chrono::steady_clock;
  enum class Say { kNothing, kStart, kEnd };

  explicit StateFault(std::chrono::seconds interval = std::chrono::seconds(60)) : interval_(interval) {}

  // One look at the state at `now`. On kStart, `starts` is how many times it started since the last start
  // said (1 when none was held back).
  Say update(bool active, Clock::time_point now, std::uint64_t& starts) noexcept {
    if (active && !active_) ++starts_;
    const bool was = active_;
    active_ = active;
    if (!active) {
      if (!was || !said_) return Say::kNothing;
      said_ = false;
      return Say::kEnd;
    }
    if (said_ || (ever_said_ && now - last_said_ < interval_)) return Say::kNothing;
    said_ = ever_said_ = true;
    last_said_ = now;
    starts = starts_;
    starts_ = 0;
    return Say::kStart;
  }

 private:
  std::chrono::seconds interval_;
  Clock::time_point last_said_{};
  std::uint64_t starts_ = 0;
  bool active_ = false, said_ = false, ever_said_ = false;
};

}  // namespace gearpulse::daemon
