#include "drivers/pulse_thread.hpp"

#include <algorithm>

#include "drivers/clock.hpp"
#include "drivers/realtime.hpp"

namespace gearpulse {
namespace {

constexpr std::int64_t kLateNs = 1'000'000;  // an edge more than this behind schedule counts as late

// What the thread applies for a requested speed: NaN and negatives are standstill.
double applicable(double speed_mps) noexcept {
  return speed_mps > 0.0 ? speed_mps : 0.0;
}

}  // namespace

PulseThread::PulseThread(PulseOutput& output, PulseThreadConfig config, std::span<RiseRecord> rise_log)
    : output_(output), config_(std::move(config)), rise_log_(rise_log) {}

PulseThread::~PulseThread() {
  stop();
}

void PulseThread::start() {
  if (thread_.started()) return;
  validate(config_.pulse);  // fail here, not on the real-time thread
  const std::int64_t t0 = monotonic_ns();
  heartbeat_ns_.store(t0, std::memory_order_relaxed);
  thread_.start([this, t0] { run(t0); });
}

void PulseThread::stop() {
  thread_.ask_stop();
  wake_.signal();  // after the flag: the thread sees it when its wait returns, or does not wait at all
  thread_.stop();
}

void PulseThread::set_speed(double speed_mps) noexcept {
  // The store comes before the signal, and the thread's wait takes the signals before it loads the speed:
  // a change it has not loaded leaves a signal, so its next wait returns at once.
  const double before = target_.exchange(speed_mps, std::memory_order_acq_rel);
  if (applicable(before) != applicable(speed_mps)) wake_.signal();
}

PulseThreadStatus PulseThread::status() const noexcept {
  PulseThreadStatus s;
  s.pulses = pulses_.load(std::memory_order_acquire);
  s.late_edges = late_edges_.load(std::memory_order_relaxed);
  s.max_late_ns = max_late_ns_.load(std::memory_order_relaxed);
  s.discarded = discarded_.load(std::memory_order_relaxed);
  s.realtime_ok = thread_.realtime_ok();
  s.memory_locked = thread_.memory_locked();
  s.realtime_refused = thread_.realtime_refused();
  s.running = thread_.running();
  s.heartbeat_ns = heartbeat_ns_.load(std::memory_order_relaxed);
  s.turns = turns_.load(std::memory_order_relaxed);
  return s;
}

void PulseThread::run(std::int64_t t0_ns) noexcept {
  thread_.enter_realtime({config_.realtime, config_.rt_priority, config_.lock_memory});
  thread_.set_running(true);

  PulseScheduler sched(config_.pulse, t0_ns);  // validated in start(): cannot throw here
  const std::int64_t heartbeat_period_ns = std::max<std::int64_t>(
      1'000'000, std::chrono::duration_cast<std::chrono::nanoseconds>(config_.heartbeat_period).count());
  double applied = 0.0;
  bool high = false;
  std::int64_t max_late = 0;
  // Each edge is committed at the instant it is written (read again after every write), so one woken late
  // writes the overdue edge and sleeps until the next: a pulse keeps its width on the line. A pass writes
  // only the edges due when it began: with an output slower than the edges (a USB adapter's round trip
  // over the gap between them) it would otherwise never end, and the thread would beat, read the speed
  // and see a stop no more.
  auto emit_due = [&](std::int64_t now) noexcept {
    for (const std::int64_t due_by = now; sched.next_edge().t_ns <= due_by; now = monotonic_ns()) {
      const PulseEdge e = sched.emit_due(now);
      if (e.kind == EdgeKind::kRise) {
        // Counted before the output takes it: what the output counts of its pulses (unheard, dropped,
        // written) is never more than the count a reader of both finds here after it. Release: a reader
        // that finds this count finds the output's counts of the pulses before it.
        pulses_.fetch_add(1, std::memory_order_release);
        output_.rise();
        high = true;
        const std::size_t n = logged_.load(std::memory_order_relaxed);
        if (n < rise_log_.size()) {
          rise_log_[n] = {e.t_ns, monotonic_ns()};
          logged_.store(n + 1, std::memory_order_release);
        }
      } else {
        output_.fall();
        high = false;
      }
      const std::int64_t late = now - e.t_ns;
      if (late > kLateNs) late_edges_.fetch_add(1, std::memory_order_relaxed);
      if (late > max_late) {
        max_late = late;
        max_late_ns_.store(late, std::memory_order_relaxed);
      }
    }
    discarded_.store(sched.discarded(), std::memory_order_relaxed);
  };

  while (!thread_.stopping()) {
    std::int64_t now = monotonic_ns();
    heartbeat_ns_.store(now, std::memory_order_relaxed);
    turns_.fetch_add(1, std::memory_order_relaxed);
    // Edges due under the old speed first: a change is only known from the moment it is seen.
    emit_due(now);
    const double target = applicable(target_.load(std::memory_order_acquire));
    if (target != applied) {
      sched.set_speed(now, target);
      applied = target;
      emit_due(now);
    }
    // Woken on time to the microsecond under SCHED_FIFO; otherwise within a thousandth of the wait
    // (WakeEvent::wait_until): at most 0.25 ms for an edge a heartbeat away, well inside kLateNs (a niced
    // thread gets a two-hundredth, over kLateNs only for an edge over 200 ms away: below 2.5 Hz).
    wake_.wait_until(std::min(sched.next_edge().t_ns, now + heartbeat_period_ns));
  }
  if (high) output_.fall();  // leave the line low
  thread_.set_running(false);
}

}  // namespace gearpulse
