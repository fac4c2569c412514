#pragma once
// The daemon's log lines while a test runs: spdlog's default logger goes to a ring buffer for the life of
// this object and is put back (with its level) when it ends, however the test ends.
#include <spdlog/sinks/ringbuffer_sink.h>
#include <spdlog/spdlog.h>

#include <cstddef>
#include <memory>
#include <string_view>
#include <vector>

namespace gearpulse::test {

class LogLines {
 public:
  LogLines() : previous_(spdlog::default_logger()), level_(spdlog::get_level()) {
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("test", sink_));
    spdlog::set_level(spdlog::level::info);
  }
  ~LogLines() {
    spdlog::set_default_logger(previous_);
    spdlog::set_level(level_);
  }
  LogLines(const LogLines&) = delete;
  LogLines& operator=(const LogLines&) = delete;

  // The levels of the lines that contain `text`, oldest first.
  [[nodiscard]] std::vector<spdlog::level::level_enum> levels(std::string_view text) const {
    std::vector<spdlog::level::level_enum> out;
    for (const auto& m : sink_->last_raw())
      if (std::string_view(m.payload.data(), m.payload.size()).find(text) != std::string_view::npos)
        out.push_back(m.level);
    return out;
  }
  // How many lines contain `text`.
  [[nodiscard]] std::size_t count(std::string_view text) const { return levels(text).size(); }

 private:
  std::shared_ptr<spdlog::sinks::ringbuffer_sink_mt> sink_ =
      std::make_shared<spdlog::sinks::ringbuffer_sink_mt>(1000);
  std::shared_ptr<spdlog::logger> previous_;
  spdlog::level::level_enum level_;
};

}  // namespace gearpulse::test
