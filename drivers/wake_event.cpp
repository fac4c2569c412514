#include "drivers/wake_event.hpp"

#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <system_error>

#include "drivers/clock.hpp"

namespace gearpulse {

WakeEvent::WakeEvent() : fd_(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)) {
  if (!fd_) throw std::system_error(errno, std::generic_category(), "eventfd");
}

void WakeEvent::signal() noexcept {
  const std::uint64_t one = 1;
  [[maybe_unused]] const ssize_t n = ::write(fd_.get(), &one, sizeof one);  // nonblocking
}

// ppoll on the eventfd rather than clock_nanosleep and a futex: one wait covers both. The relative
// timeout is taken from the clock right here and the kernel turns it back into an absolute hrtimer expiry
// on entry, so the wake-up is off by the microsecond between the two clock reads, as against
// clock_nanosleep(TIMER_ABSTIME). Under SCHED_FIFO ppoll's timer slack is 0 (select_estimate_accuracy
// waives it for real-time tasks, as clock_nanosleep does); otherwise it is the larger of the thread's
// timer slack (50 us, clock_nanosleep's alone) and a thousandth of the wait (a niced thread: a
// two-hundredth). The counter is read back to zero once the eventfd is seen signalled: every signal the
// read takes was given before it, so what its giver published before signalling is there to be seen.
void WakeEvent::wait_until(std::int64_t t_ns) noexcept {
  pollfd pfd{fd_.get(), POLLIN, 0};
  const timespec rel = to_timespec(std::max<std::int64_t>(0, t_ns - monotonic_ns()));
  if (::ppoll(&pfd, 1, &rel, nullptr) <= 0 || !(pfd.revents & POLLIN)) return;  // the time, or EINTR
  take_signals();
}

void WakeEvent::take_signals() noexcept {
  std::uint64_t count = 0;
  [[maybe_unused]] const ssize_t n = ::read(fd_.get(), &count, sizeof count);  // nonblocking: never waits
}

}  // namespace gearpulse
