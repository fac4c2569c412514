#pragma once
// The thread a device runs on (the capture thread, the pulse thread): started once, asked to stop by a
// flag its loop polls, joined; it enters real time as configured on the thread itself, and says whether
// it got it and whether it runs, for the owner's statistics. The owner's destructor calls stop() before
// anything the thread uses is destroyed.
#include <atomic>
#include <thread>
#include <utility>

#include "drivers/realtime.hpp"

namespace gearpulse {

class DeviceThread {
 public:
  DeviceThread() = default;
  ~DeviceThread() { stop(); }
  DeviceThread(const DeviceThread&) = delete;
  DeviceThread& operator=(const DeviceThread&) = delete;

  // Runs `body` on a new thread; nothing if one runs already. Throws std::system_error if no thread can
  // be had.
  template <class Body>
  void start(Body&& body) {
    if (thread_.joinable()) return;
    stop_.store(false);
    thread_ = std::thread(std::forward<Body>(body));
  }
  // Asks the thread to stop and joins it.
  void stop() {
    ask_stop();
    if (thread_.joinable()) thread_.join();
  }
  // Asks the thread to stop without joining it: for an owner that then wakes the thread's wait.
  void ask_stop() noexcept { stop_.store(true); }

  [[nodiscard]] bool started() const noexcept { return thread_.joinable(); }
  // On the thread: whether stop() was asked.
  [[nodiscard]] bool stopping() const noexcept { return stop_.load(std::memory_order_relaxed); }
  // On the thread: real-time set-up as `request` asks (failures are reported in the result, not fatal).
  RealtimeResult enter_realtime(const RealtimeRequest& request) noexcept {
    const RealtimeResult rt = make_realtime(request);
    realtime_ok_.store(rt.fifo);
    memory_locked_.store(rt.memory_locked);
    realtime_refused_.store((request.fifo && !rt.fifo) || (request.lock_memory && !rt.memory_locked));
    return rt;
  }
  // On the thread: its loop runs (true once set up, false as it ends).
  void set_running(bool running) noexcept { running_.store(running); }

  [[nodiscard]] bool running() const noexcept { return running_.load(std::memory_order_relaxed); }
  [[nodiscard]] bool realtime_ok() const noexcept { return realtime_ok_.load(std::memory_order_relaxed); }
  [[nodiscard]] bool memory_locked() const noexcept { return memory_locked_.load(std::memory_order_relaxed); }
  // What enter_realtime() was asked for was refused, in part or whole (SCHED_FIFO, the memory lock).
  [[nodiscard]] bool realtime_refused() const noexcept {
    return realtime_refused_.load(std::memory_order_relaxed);
  }

 private:
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> running_{false};
  std::atomic<bool> realtime_ok_{false};
  std::atomic<bool> memory_locked_{false};
  std::atomic<bool> realtime_refused_{false};
};

}  // namespace gearpulse
