#pragma once
// Real-time set-up for the calling thread, shared by the capture and pulse threads: SCHED_FIFO at a
// priority, and memory locked as it is touched so a page once used is never paged out to delay a sample
// or an edge (the calling thread's stack is touched at once). Both usually need root or CAP_SYS_NICE /
// CAP_IPC_LOCK; failures are reported, never fatal.
namespace gearpulse {

struct RealtimeRequest {
  bool fifo = false;         // SCHED_FIFO for the calling thread
  int priority = 70;         // 1..99
  bool lock_memory = false;  // mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT), process-wide
};

struct RealtimeResult {
  bool fifo = false;           // SCHED_FIFO granted
  bool memory_locked = false;  // mlockall succeeded
};

// Applies what `request` asks for; what was not asked for reads false.
RealtimeResult make_realtime(const RealtimeRequest& request) noexcept;

// Puts the calling thread under SCHED_FIFO at `priority`, or back under the normal policy; true if done.
bool set_fifo(bool fifo, int priority) noexcept;

}  // namespace gearpulse
