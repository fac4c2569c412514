#pragma once
// The daemon's log as a queue: every thread's lines go into a bounded queue that one thread of its own
// writes to the sink (stderr, which systemd hands to the journal). A journal that stops taking lines (a
// slow SD card flushing, journald restarting) then stalls only that thread: the tracker keeps stepping the
// synthesis and the main thread keeps petting the watchdog, which a write blocked for WatchdogSec would
// otherwise cost a restart, and the gear belief with it in the middle of an outage. When the queue is full
// the oldest line waiting gives way, and the first line written after such a gap says how many were lost.
#include <cstddef>
#include <cstdint>
#include <memory>

#include <spdlog/async.h>
#include <spdlog/sinks/sink.h>
#include <spdlog/spdlog.h>

namespace gearpulse::daemon {

class LogQueue {
 public:
  // Makes spdlog's default logger, named `name`, write through the queue (at most `capacity` lines
  // waiting) to `sink`, for the life of this object.
  LogQueue(const char* name, std::shared_ptr<spdlog::sinks::sink> sink, std::size_t capacity = 1024);
  // Writes out every line still waiting (which waits for the sink), then puts the previous default logger
  // back. No thread may log between the two (the daemon's have all ended by then).
  ~LogQueue();
  LogQueue(const LogQueue&) = delete;
  LogQueue& operator=(const LogQueue&) = delete;

  // Lines lost so far to a full queue.
  [[nodiscard]] std::uint64_t dropped() const;

 private:
  std::shared_ptr<spdlog::logger> previous_;
  std::shared_ptr<spdlog::details::thread_pool> pool_;
};

}  // namespace gearpulse::daemon
