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

}  // namespace gearpulse::daemon
