#pragma once
// Pulse output on a pseudo-terminal: one byte ('P') per pulse, written at its rising edge, so a reader
// counts pulses by counting bytes. The slave side is published as a symlink at the configured path.
//
// Readers come and go: the master stays open for the life of the object, writes are non-blocking, and a
// pulse emitted while no reader has the slave open is counted in unheard() rather than queued, so a
// reader that (re)opens the device sees only pulses emitted after it opened. A reader that has the device
// open but stops reading gets no old pulses either when it resumes: pulses that have waited longer than
// max_age in its queue are dropped (counted in overflowed()), as a wire would not have kept them.
#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <string>

#include "drivers/pulse_output.hpp"
#include "drivers/unique_fd.hpp"

namespace gearpulse {

class PtyOutput final : public PulseOutput {
 public:
  // Creates the pair in raw mode and the symlink `link` -> slave. A stale symlink at `link` is replaced;
  // anything else there, a missing directory, or a link another live process publishes (it holds the
  // lock file "<link>.lock") throws std::runtime_error with a one-line reason.
  explicit PtyOutput(std::filesystem::path link, std::chrono::nanoseconds max_age = std::chrono::seconds(2));
  ~PtyOutput() override;  // removes the symlink if it still points at this PTY
  PtyOutput(const PtyOutput&) = delete;
  PtyOutput& operator=(const PtyOutput&) = delete;

  void rise() noexcept override;
  void fall() noexcept override {}
  [[nodiscard]] std::uint64_t errors() const noexcept override {
    return errors_.load(std::memory_order_acquire);  // last_error() then holds the errno of a counted failure
  }
  [[nodiscard]] int last_error() const noexcept override {
    return last_error_.load(std::memory_order_relaxed);
  }
  [[nodiscard]] std::uint64_t dropped() const noexcept override { return overflowed(); }
  // Whether a process has the slave open now (the master reports no hang-up).
  [[nodiscard]] bool has_reader() const noexcept override;
  [[nodiscard]] std::string describe() const override;

  [[nodiscard]] const std::filesystem::path& link() const noexcept { return link_; }
  [[nodiscard]] const std::string& slave_name() const noexcept { return slave_name_; }
  [[nodiscard]] std::uint64_t written() const noexcept { return written_.load(std::memory_order_relaxed); }
  // Pulses emitted while no reader had the slave open. Acquire: the pulse thread's count of them (counted
  // before rise()) is then read at least as large.
  [[nodiscard]] std::uint64_t unheard() const noexcept override {
    return unheard_.load(std::memory_order_acquire);
  }
  // Pulses dropped because a reader that is present did not keep up (its input queue was full, or they
  // had waited in it longer than max_age).
  [[nodiscard]] std::uint64_t overflowed() const noexcept {
    return overflowed_.load(std::memory_order_relaxed);
  }

 private:
  std::filesystem::path link_;
  std::string slave_name_;
  UniqueFd lock_;  // flock on "<link>.lock", held for the object's life (released after the master)
  UniqueFd master_;
  bool idle_ = true;  // pulse-thread state: no reader had the slave open at the last pulse
  // Pulse-thread state for the age of the reader's queue: at each look (at a pulse, at most every quarter of
  // max_age) the time and the count of pulses written by then, the last kLooks of them.
  void drop_stale(std::int64_t now_ns) noexcept;
  struct Look {
    std::int64_t t_ns = 0;
    std::uint64_t written = 0;
  };
  static constexpr std::size_t kLooks = 16;
  std::array<Look, kLooks> looks_{};
  std::size_t looks_next_ = 0;
  std::int64_t max_age_ns_;
  std::atomic<std::uint64_t> written_{0};
  std::atomic<std::uint64_t> unheard_{0};
  std::atomic<std::uint64_t> overflowed_{0};
  std::atomic<std::uint64_t> errors_{0};
  std::atomic<int> last_error_{0};
};

}  // namespace gearpulse
