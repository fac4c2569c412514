#include "daemon/watchdog.hpp"

namespace gearpulse::daemon {

std::vector<std::string> stalled_threads(std::span<const ThreadBeat> beats, std::int64_t now_ns,
                                         std::int64_t stall_ns) {
  std::vector<std::string> hung;
  for (const ThreadBeat& b : beats)
    if (b.ended || now_ns - b.last_ns > stall_ns) hung.push_back(b.name);
  return hung;
}

bool WatchdogGate::tick(const std::vector<std::string>& stalled) {
  const bool newly = !stalled.empty() && stalled != last_stalled_;
  last_stalled_ = stalled;
  if (!stalled.empty()) {
    ++withheld_;
    return newly;
  }
  ++fed_;
  if (feed_) feed_();
  return false;
}

}  // namespace gearpulse::daemon
