#include "drivers/gpio_output.hpp"

#include <gpiod.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <stdexcept>

namespace gearpulse {
namespace {

[[noreturn]] void fail(const std::string& chip, unsigned offset, const std::string& what, int err = 0) {
  std::string msg = "gpio output " + chip + " line " + std::to_string(offset) + ": " + what;
  if (err) msg += ": " + std::string(std::strerror(err));
  throw std::runtime_error(msg);
}

}  // namespace

bool gpio_chip_available() {
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/dev", ec))
    if (entry.path().filename().string().rfind("gpiochip", 0) == 0) return true;
  return false;
}

GpioOutput::GpioOutput(const std::string& chip, unsigned offset) : chip_name_(chip), offset_(offset) {
  errno = 0;
  chip_.reset(::gpiod_chip_open_lookup(chip.c_str()));  // name, path or number
  if (!chip_) fail(chip, offset, "cannot open the GPIO chip", errno ? errno : ENODEV);
  if (offset >= ::gpiod_chip_num_lines(chip_.get())) {
    const unsigned n = ::gpiod_chip_num_lines(chip_.get());
    fail(chip, offset, "offset out of range (the chip has " + std::to_string(n) + " lines)");
  }
  line_ = ::gpiod_chip_get_line(chip_.get(), offset);
  if (!line_) {
    const int err = errno;
    fail(chip, offset, "cannot get the line", err);
  }
  if (::gpiod_line_is_used(line_)) {
    const char* owner = ::gpiod_line_consumer(line_);
    const std::string who = owner ? owner : "the kernel or another process";
    fail(chip, offset, "line is busy (used by " + who + ")");
  }
  if (::gpiod_line_request_output(line_, kConsumer, 0) != 0) {
    const int err = errno;
    fail(chip, offset, err == EBUSY ? "line is busy" : "cannot request the line as output", err);
  }
}

GpioOutput::~GpioOutput() {
  if (line_) {
    ::gpiod_line_set_value(line_, 0);
    ::gpiod_line_release(line_);
  }
}

void GpioOutput::ChipCloser::operator()(gpiod_chip* chip) const noexcept {
  ::gpiod_chip_close(chip);
}

void GpioOutput::set(int value) noexcept {
  if (::gpiod_line_set_value(line_, value) == 0) return;
  last_error_.store(errno != 0 ? errno : EIO, std::memory_order_relaxed);
  errors_.fetch_add(1, std::memory_order_release);  // publishes last_error_ with the count
}

std::string GpioOutput::describe() const {
  return "gpio " + chip_name_ + " line " + std::to_string(offset_);
}

}  // namespace gearpulse
