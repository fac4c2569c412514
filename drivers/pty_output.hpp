#pragma once
// Pulse output on a pseudo-terminal: one byte ('P') per pulse, written at its rising edge, so a reader
// counts pulses by counting bytes. The slave side is published as a symlink at the configured path.
//
// Readers come and go: the master stays open for the life of the object, writes are non-blocking, and a
// pulse emitted while no reader has the slave open is counted in unheard() rather than queued, so a
// reader that (re)opens the device sees only pulses emitted after it opened.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <string>

#include "drivers/pulse_output.hpp"

namespace gearpulse {

class PtyOutput final : public PulseOutput {
 public:
  // Creates the pair in raw mode and the symlink `link` -> slave. A stale symlink at `link` is replaced;
  // anything else there, or a missing directory, throws std::runtime_error with a one-line reason.
  explicit PtyOutput(std::filesystem::path link);
  ~PtyOutput() override;  // removes the symlink if it still points at this PTY
  PtyOutput(const PtyOutput&) = delete;
  PtyOutput& operator=(const PtyOutput&) = delete;

  void rise() noexcept override;
  void fall() noexcept override {}
  [[nodiscard]] std::uint64_t errors() const noexcept override {
    return errors_.load(std::memory_order_relaxed);
  }
  [[nodiscard]] std::uint64_t dropped() const noexcept override { return overflowed(); }
  [[nodiscard]] std::string describe() const override;

  [[nodiscard]] const std::filesystem::path& link() const noexcept { return link_; }
  [[nodiscard]] const std::string& slave_name() const noexcept { return slave_name_; }
  [[nodiscard]] std::uint64_t written() const noexcept { return written_.load(std::memory_order_relaxed); }
  // Pulses emitted while no reader had the slave open.
  [[nodiscard]] std::uint64_t unheard() const noexcept { return unheard_.load(std::memory_order_relaxed); }
  // Pulses dropped because a reader that is present did not keep up (its input queue was full).
  [[nodiscard]] std::uint64_t overflowed() const noexcept {
    return overflowed_.load(std::memory_order_relaxed);
  }

 private:
  std::filesystem::path link_;
  std::string slave_name_;
  int master_ = -1;
  bool idle_ = true;  // pulse-thread state: no reader had the slave open at the last pulse
  std::atomic<std::uint64_t> written_{0};
  std::atomic<std::uint64_t> unheard_{0};
  std::atomic<std::uint64_t> overflowed_{0};
  std::atomic<std::uint64_t> errors_{0};
};

}  // namespace gearpulse
