#pragma once
// sd_notify: READY, STATUS, WATCHDOG, STOPPING. Harmless no-ops when not started by systemd.
#include <chrono>
#include <string>

namespace gearpulse::daemon::systemd {

void ready(const std::string& status) noexcept;
void status(const std::string& text) noexcept;
void watchdog() noexcept;
void stopping() noexcept;
// The watchdog interval systemd expects pings within (zero when the watchdog is off).
[[nodiscard]] std::chrono::microseconds watchdog_interval() noexcept;

}  // namespace gearpulse::daemon::systemd
