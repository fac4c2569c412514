#include "drivers/realtime.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>

namespace gearpulse {

RealtimeResult make_realtime(const RealtimeRequest& request) noexcept {
  RealtimeResult result;
  if (request.fifo) {
    sched_param sp{};
    sp.sched_priority = request.priority;
    result.fifo = ::pthread_setschedparam(::pthread_self(), SCHED_FIFO, &sp) == 0;
  }
  if (request.lock_memory) result.memory_locked = ::mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
  return result;
}

bool set_fifo(bool fifo, int priority) noexcept {
  sched_param sp{};
  sp.sched_priority = fifo ? priority : 0;
  return ::pthread_setschedparam(::pthread_self(), fifo ? SCHED_FIFO : SCHED_OTHER, &sp) == 0;
}

}  // namespace gearpulse
