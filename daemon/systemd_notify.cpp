#include "daemon/systemd_notify.hpp"

#include <systemd/sd-daemon.h>

namespace gearpulse::daemon::systemd {

void ready(const std::string& status) noexcept {
  sd_notify(0, ("READY=1\nSTATUS=" + status).c_str());
}

void status(const std::string& text) noexcept {
  sd_notify(0, ("STATUS=" + text).c_str());
}

void watchdog() noexcept {
  sd_notify(0, "WATCHDOG=1");
}

void stopping() noexcept {
  sd_notify(0, "STOPPING=1\nSTATUS=stopping");
}

std::chrono::microseconds watchdog_interval() noexcept {
  std::uint64_t usec = 0;
  if (sd_watchdog_enabled(0, &usec) > 0) return std::chrono::microseconds(usec);
  return std::chrono::microseconds(0);
}

}  // namespace gearpulse::daemon::systemd
