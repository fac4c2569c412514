#include "daemon/log_queue.hpp"

#include <pthread.h>

#include <csignal>

#include <string>
#include <utility>

#include <fmt/format.h>
#include <spdlog/async_logger.h>

namespace gearpulse::daemon {
namespace {

// Runs on the queue's thread only: before the first line after lines were lost, a line saying how many.
class GapNotingSink final : public spdlog::sinks::sink {
 public:
  GapNotingSink(std::shared_ptr<spdlog::sinks::sink> inner, spdlog::details::thread_pool& pool)
      : inner_(std::move(inner)), pool_(pool) {}

  void log(const spdlog::details::log_msg& msg) override {
    const std::size_t lost = pool_.overrun_counter();
    if (lost != noted_) {
      const std::string text = fmt::format(
          "log: {} line(s) lost before this one (the journal did not take them in time)", lost - noted_);
      noted_ = lost;
      inner_->log(spdlog::details::log_msg(msg.time, msg.source, msg.logger_name, spdlog::level::warn, text));
    }
    inner_->log(msg);
  }
  void flush() override { inner_->flush(); }
  void set_pattern(const std::string& pattern) override { inner_->set_pattern(pattern); }
  void set_formatter(std::unique_ptr<spdlog::formatter> formatter) override {
    inner_->set_formatter(std::move(formatter));
  }

 private:
  std::shared_ptr<spdlog::sinks::sink> inner_;
  spdlog::details::thread_pool& pool_;
  std::size_t noted_ = 0;
};

}  // namespace

LogQueue::LogQueue(const char* name, std::shared_ptr<spdlog::sinks::sink> sink, std::size_t capacity)
    : previous_(spdlog::default_logger()),
      // The queue's thread takes no signal: the daemon takes SIGTERM, SIGINT and SIGHUP on its main thread
      // (a signalfd), and a thread started before it blocks them would meet them with the default action.
      pool_(std::make_shared<spdlog::details::thread_pool>(capacity, 1, [] {
        sigset_t all;
        ::sigfillset(&all);
        ::pthread_sigmask(SIG_BLOCK, &all, nullptr);
      })) {
  auto noting = std::make_shared<GapNotingSink>(std::move(sink), *pool_);
  spdlog::set_default_logger(std::make_shared<spdlog::async_logger>(
      name, std::move(noting), pool_, spdlog::async_overflow_policy::overrun_oldest));
}

LogQueue::~LogQueue() {
  // The pool's destructor queues its thread's end behind every waiting line and joins it; the logger and
  // its sinks are then released on this thread, after the queue's thread is gone.
  pool_.reset();
  spdlog::set_default_logger(previous_);
}

std::uint64_t LogQueue::dropped() const {
  return pool_->overrun_counter();
}

}  // namespace gearpulse::daemon
