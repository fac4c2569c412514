#pragma once
// A SliceRunner that runs the first slice on the calling thread and each other slice on a thread of its
// own, started for the pass and joined before run() returns: for fits on a machine with cores to spare
// (`gearpulse fit`, the daemon's retrainer). Header-only, so programs that open no device need not link
// the drivers.
//
// What a slice throws (a bad_alloc under the memory limit of a daemon that locked its memory) reaches the
// caller once every slice has returned, as it would from slices run in turn: an exception leaving a thread's
// function would end the process. A slice no thread can be started for (the system's thread or memory
// limit) runs on the calling thread.
#include <exception>
#include <system_error>
#include <thread>
#include <vector>

#include "core/slice_runner.hpp"

namespace gearpulse {

class ThreadSliceRunner final : public SliceRunner {
 public:
  void run(std::size_t count, const std::function<void(std::size_t)>& task) override {
    if (count == 0) return;
    std::vector<std::exception_ptr> errors(count);
    const auto guarded = [&task, &errors](std::size_t i) noexcept {
      try {
        task(i);
      } catch (...) {
        errors[i] = std::current_exception();
      }
    };
    {
      std::vector<std::jthread> others;
      others.reserve(count - 1);
      std::size_t started = 1;
      for (; started < count; ++started) {
        try {
          others.emplace_back(guarded, started);
        } catch (const std::system_error&) {
          break;
        }
      }
      for (std::size_t i = started; i < count; ++i)
        guarded(i);
      guarded(0);
    }  // the others join here
    for (const std::exception_ptr& e : errors)
      if (e) std::rethrow_exception(e);
  }
};

}  // namespace gearpulse
