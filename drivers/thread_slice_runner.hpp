#pragma once
// A SliceRunner that runs the first slice on the calling thread and each other slice on a thread of its
// own, started for the pass and joined before run() returns: for fits on a machine with cores to spare
// (`gearpulse fit`, the daemon's retrainer). Header-only, so programs that open no device need not link
// the drivers.
#include <thread>
#include <vector>

#include "core/slice_runner.hpp"

namespace gearpulse {

class ThreadSliceRunner final : public SliceRunner {
 public:
  void run(std::size_t count, const std::function<void(std::size_t)>& task) override {
    if (count == 0) return;
    std::vector<std::jthread> others;
    others.reserve(count - 1);
    for (std::size_t i = 1; i < count; ++i)
      others.emplace_back([&task, i] { task(i); });
    task(0);
  }  // the others join here
};

}  // namespace gearpulse
