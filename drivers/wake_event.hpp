#pragma once
// A wake-up one thread waits on and any thread gives: an eventfd the waiter polls with a deadline. A
// signal given while nobody waits is kept (the eventfd's counter), so the next wait returns at once: a
// waiter that looks for its work after a wait returned, and a giver that signals after it published the
// work, lose no wake-up. signal() and wait_until() never allocate, lock in user space or throw: for the
// real-time threads (the capture, the pulse thread) and the tracker. A thread that waits on descriptors
// of its own as well (the control server's epoll) waits on fd() among them and takes the signals itself.
#include <cstdint>

#include "drivers/unique_fd.hpp"

namespace gearpulse {

class WakeEvent {
 public:
  WakeEvent();  // throws std::system_error if no eventfd can be had
  WakeEvent(const WakeEvent&) = delete;
  WakeEvent& operator=(const WakeEvent&) = delete;

  // Makes the current or the next wait return (one non-blocking write).
  void signal() noexcept;
  // Waits until CLOCK_MONOTONIC `t_ns` (at once if it has passed) or a signal, and takes the signals given
  // so far: a signal given after this returns makes the next wait return. One thread waits at a time.
  void wait_until(std::int64_t t_ns) noexcept;

  // Readable (POLLIN) while a signal is pending: for a waiter that polls it beside other descriptors.
  [[nodiscard]] int fd() const noexcept { return fd_.get(); }
  // Takes the signals given so far without waiting, as wait_until() does when one wakes it: a waiter that
  // saw fd() readable calls it before it looks for its work, or a level-triggered poll wakes it again.
  void take_signals() noexcept;

 private:
  UniqueFd fd_;
};

}  // namespace gearpulse
