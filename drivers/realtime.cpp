#include "drivers/realtime.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>

#include <cstddef>

namespace gearpulse {
namespace {

// How much of the calling thread's stack is touched once its memory is locked: far more than the capture
// and pulse loops use, so none of their stack pages is first touched (a page fault) inside the loop.
constexpr std::size_t kStackPrefault = 256 * 1024;
constexpr std::size_t kPage = 4096;

void prefault_stack() noexcept {
  [[maybe_unused]] volatile unsigned char stack[kStackPrefault];
  for (std::size_t i = 0; i < kStackPrefault; i += kPage)
    stack[i] = 0;
}

}  // namespace

RealtimeResult make_realtime(const RealtimeRequest& request) noexcept {
  RealtimeResult result;
  if (request.fifo) result.fifo = set_fifo(true, request.priority);
  if (request.lock_memory) {
    // Pages are locked as they are first touched (MCL_ONFAULT), not made resident all at once: every
    // thread's 8 MB stack and every reserved heap page would otherwise be (the demo drive's daemon held
    // 78 MiB so, 17.5 MiB with MCL_ONFAULT; scripts/measure_daemon.sh with GEARPULSE_REALTIME=true).
    // What the real-time loops use is touched before they run: their buffers when allocated, their
    // stacks here. A kernel without MCL_ONFAULT (before 4.4) locks it all.
    result.memory_locked =
        ::mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT) == 0 || ::mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
    if (result.memory_locked) prefault_stack();
  }
  return result;
}

bool set_fifo(bool fifo, int priority) noexcept {
  sched_param sp{};
  sp.sched_priority = fifo ? priority : 0;
  return ::pthread_setschedparam(::pthread_self(), fifo ? SCHED_FIFO : SCHED_OTHER, &sp) == 0;
}

}  // namespace gearpulse
