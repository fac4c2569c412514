#pragma once
// Where the slices of a pass over many samples run. The code in core/ splits its large passes into
// independent slices (the same split whatever runs them, so results do not depend on it) and starts no
// thread of its own: the caller decides. Without a runner the slices run in turn on the calling thread;
// drivers/thread_slice_runner.hpp runs them on threads.
#include <cstddef>
#include <functional>

namespace gearpulse {

class SliceRunner {
 public:
  virtual ~SliceRunner() = default;
  // Calls task(i) for every i in [0, count) and returns when every call has returned. The calls touch
  // disjoint data and may run at once.
  virtual void run(std::size_t count, const std::function<void(std::size_t)>& task) = 0;
};

}  // namespace gearpulse
