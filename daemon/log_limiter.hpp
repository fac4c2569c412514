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

}  // namespace gearpulse::daemon
