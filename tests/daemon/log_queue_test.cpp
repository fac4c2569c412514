// The daemon's log queue: no thread waits for a sink that has stopped taking lines, and the lines lost
// meanwhile are said.
#include <catch2/catch.hpp>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <spdlog/sinks/base_sink.h>
#include <spdlog/spdlog.h>

#include "daemon/log_queue.hpp"

using gearpulse::daemon::LogQueue;

namespace {

// A sink that keeps its lines and, while closed, holds whoever writes to it (a journal that stalls).
class GateSink final : public spdlog::sinks::base_sink<std::mutex> {
 public:
  void open() {
    {
      std::lock_guard lock(gate_mutex_);
      open_ = true;
    }
    gate_.notify_all();
  }
  // Waits until a line is held at the closed gate.
  void wait_held() {
    std::unique_lock gate(gate_mutex_);
    gate_.wait(gate, [this] { return held_; });
  }
  std::vector<std::string> lines() {
    std::lock_guard lock(mutex_);
    return lines_;
  }

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override {
    std::unique_lock gate(gate_mutex_);
    held_ = !open_;
    gate_.notify_all();
    gate_.wait(gate, [this] { return open_; });
    lines_.emplace_back(msg.payload.data(), msg.payload.size());
  }
  void flush_() override {}

 private:
  std::mutex gate_mutex_;
  std::condition_variable gate_;
  bool open_ = false;
  bool held_ = false;
  std::vector<std::string> lines_;
};

// Logs lines "line 0" .. "line n-1" on a thread of its own, the rest once `after_first` returns; the
// future is ready once every call returned.
template <typename F>
std::future<void> log_lines(int n, F after_first) {
  return std::async(std::launch::async, [n, after_first] {
    spdlog::info("line 0");
    after_first();
    for (int i = 1; i < n; ++i)
      spdlog::info("line {}", i);
  });
}

}  // namespace

TEST_CASE("log queue: a stalled sink holds no thread that logs, and the lines lost are said",
          "[daemon][log]") {
  const auto level = spdlog::get_level();
  spdlog::set_level(spdlog::level::info);
  auto sink = std::make_shared<GateSink>();
  std::vector<std::string> lines;
  std::uint64_t dropped = 0;
  {
    LogQueue queue("log-queue-test", sink, 8);
    // The first line reaches the sink and stalls there before the others come.
    auto done = log_lines(100, [&sink] { sink->wait_held(); });
    const bool returned = done.wait_for(std::chrono::seconds(20)) == std::future_status::ready;
    sink->open();  // whatever happened, let the writer go so the test can end
    done.wait();
    CHECK(returned);
    dropped = queue.dropped();
  }  // every line still queued is written out here
  spdlog::set_level(level);
  lines = sink->lines();

  // The sink stalled on the first line; of the 99 after it the queue kept the newest 8.
  CHECK(dropped == 91);
  REQUIRE(lines.size() >= 2);
  CHECK(lines.front() == "line 0");
  CHECK(lines.back() == "line 99");
  const std::string note = "log: " + std::to_string(dropped) +
                           " line(s) lost before this one (the journal did not take them in time)";
  CHECK(std::count(lines.begin(), lines.end(), note) == 1);
  // Every line is either written or counted as lost, and the note stands just before the first line after
  // the gap.
  CHECK(lines.size() == 100 - dropped + 1);
  const auto at = std::find(lines.begin(), lines.end(), note);
  REQUIRE(at != lines.end());
  REQUIRE(at + 1 != lines.end());
  CHECK(*(at + 1) == "line " + std::to_string(1 + dropped));
}

TEST_CASE("log queue: lines are written in order, all of them, before the queue ends", "[daemon][log]") {
  const auto previous = spdlog::default_logger();
  auto sink = std::make_shared<GateSink>();
  sink->open();
  {
    LogQueue queue("log-queue-test", sink, 1024);
    CHECK(spdlog::default_logger() != previous);
    log_lines(500, [] {}).wait();
    CHECK(queue.dropped() == 0);
  }
  CHECK(spdlog::default_logger() == previous);
  const auto lines = sink->lines();
  REQUIRE(lines.size() == 500);
  for (int i = 0; i < 500; ++i)
    CHECK(lines[static_cast<std::size_t>(i)] == "line " + std::to_string(i));
}
