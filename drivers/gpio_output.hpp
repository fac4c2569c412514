#pragma once
// Pulse output on a GPIO line through libgpiod 1.6: the line is requested as an output with consumer
// "gearpulse", driven high for the pulse width and low otherwise, and left low on close.
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "drivers/pulse_output.hpp"

struct gpiod_chip;
struct gpiod_line;

namespace gearpulse {

class GpioOutput final : public PulseOutput {
 public:
  static constexpr const char* kConsumer = "gearpulse";

  // `chip`: a name ("gpiochip0"), a path ("/dev/gpiochip0") or a number ("0"). Throws std::runtime_error
  // with a one-line reason: no such chip, offset out of range, line busy (naming its consumer).
  GpioOutput(const std::string& chip, unsigned offset);
  ~GpioOutput() override;  // drives the line low, then releases it
  GpioOutput(const GpioOutput&) = delete;
  GpioOutput& operator=(const GpioOutput&) = delete;

  void rise() noexcept override { set(1); }
  void fall() noexcept override { set(0); }
  [[nodiscard]] std::uint64_t errors() const noexcept override {
    return errors_.load(std::memory_order_acquire);  // last_error() then holds the errno of a counted failure
  }
  [[nodiscard]] int last_error() const noexcept override {
    return last_error_.load(std::memory_order_relaxed);
  }
  [[nodiscard]] std::string describe() const override;

 private:
  void set(int value) noexcept;  // drives the line; a failure is counted with its errno
  std::string chip_name_;
  unsigned offset_;
  struct ChipCloser {
    void operator()(gpiod_chip* chip) const noexcept;
  };
  std::unique_ptr<gpiod_chip, ChipCloser> chip_;  // closed after the line is released
  gpiod_line* line_ = nullptr;
  std::atomic<std::uint64_t> errors_{0};
  std::atomic<int> last_error_{0};
};

// True if at least one GPIO chip device exists (tests skip visibly otherwise).
[[nodiscard]] bool gpio_chip_available();

}  // namespace gearpulse
