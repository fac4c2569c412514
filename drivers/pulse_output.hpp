#pragma once
// The device end of the pulse train. The pulse thread calls rise() at every rising edge and fall() at
// every falling edge; both run on the real-time path, so they never block, allocate, log or throw:
// failures are counted and the slower threads read the counters.
#include <cstdint>
#include <string>

namespace gearpulse {

class PulseOutput {
 public:
  virtual ~PulseOutput() = default;
  virtual void rise() noexcept = 0;
  virtual void fall() noexcept = 0;
  // Writes to the device that failed (or found nobody listening) since construction.
  [[nodiscard]] virtual std::uint64_t errors() const noexcept = 0;
  // The errno of the most recent of those failures (0: none yet), for the logs and the status.
  [[nodiscard]] virtual int last_error() const noexcept { return 0; }
  // Pulses a reader that is there did not take (its queue was full): it has stopped reading, or reads
  // too slowly. A line driven by level (GPIO) has no queue and drops nothing.
  [[nodiscard]] virtual std::uint64_t dropped() const noexcept { return 0; }
  // False while the device knows that nobody takes its pulses (a PTY that no process holds open). A line
  // driven by level (GPIO) cannot tell, and says true. Any thread may ask.
  [[nodiscard]] virtual bool has_reader() const noexcept { return true; }
  // Pulses emitted while nobody took them (has_reader() false): discarded, not queued for a later reader.
  [[nodiscard]] virtual std::uint64_t unheard() const noexcept { return 0; }
  // One line for logs and status ("pty /run/gearpulse/pulse -> /dev/pts/3").
  [[nodiscard]] virtual std::string describe() const = 0;
};

// Counts edges and does nothing else: output kind "none", and a stand-in for tests.
class NullPulseOutput final : public PulseOutput {
 public:
  void rise() noexcept override { ++rises_; }
  void fall() noexcept override { ++falls_; }
  [[nodiscard]] std::uint64_t errors() const noexcept override { return 0; }
  [[nodiscard]] std::string describe() const override { return "none"; }
  [[nodiscard]] std::uint64_t rises() const noexcept { return rises_; }
  [[nodiscard]] std::uint64_t falls() const noexcept { return falls_; }

 private:
  std::uint64_t rises_ = 0;
  std::uint64_t falls_ = 0;
};

}  // namespace gearpulse
