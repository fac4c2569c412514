#pragma once
// The pulse output of a device that may open late (a GPIO line still held by another process, a USB GPIO
// adapter that enumerates after the daemon started, a PTY whose directory appears later).
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "drivers/pulse_output.hpp"

namespace gearpulse {

// What the pulse thread drives: the device once it is open; until then a stand-in that counts the pulses.
// The device is attached once, by the main thread, while the pulse thread runs: the thread finds it
// through an atomic pointer at its next edge, and it is freed only after the thread has stopped. A second
// device is refused (false, and it is closed at once): the pulse thread may be driving the first.
class LateOutput final : public PulseOutput {
 public:
  [[nodiscard]] bool attach(std::unique_ptr<PulseOutput> device) noexcept {
    if (device_ || !device) return false;
    device_ = std::move(device);
    current_.store(device_.get(), std::memory_order_release);
    return true;
  }
  [[nodiscard]] bool attached() const noexcept { return current_.load(std::memory_order_acquire) != &none_; }
  void rise() noexcept override { current_.load(std::memory_order_acquire)->rise(); }
  void fall() noexcept override { current_.load(std::memory_order_acquire)->fall(); }
  [[nodiscard]] std::uint64_t errors() const noexcept override {
    return current_.load(std::memory_order_acquire)->errors();
  }
  [[nodiscard]] int last_error() const noexcept override {
    return current_.load(std::memory_order_acquire)->last_error();
  }
  [[nodiscard]] std::uint64_t dropped() const noexcept override {
    return current_.load(std::memory_order_acquire)->dropped();
  }
  [[nodiscard]] bool has_reader() const noexcept override {
    return current_.load(std::memory_order_acquire)->has_reader();
  }
  [[nodiscard]] std::uint64_t unheard() const noexcept override {
    return current_.load(std::memory_order_acquire)->unheard();
  }
  [[nodiscard]] std::string describe() const override {
    return current_.load(std::memory_order_acquire)->describe();
  }

 private:
  NullPulseOutput none_;
  std::unique_ptr<PulseOutput> device_;
  std::atomic<PulseOutput*> current_{&none_};
};

}  // namespace gearpulse
