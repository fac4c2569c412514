// ThreadSliceRunner: every slice runs once, and what a slice on another thread throws reaches the caller
// after every slice has returned (it would otherwise end the process).
#include <catch2/catch.hpp>

#include <atomic>
#include <new>
#include <stdexcept>
#include <thread>
#include <vector>

#include "drivers/thread_slice_runner.hpp"

using gearpulse::ThreadSliceRunner;

TEST_CASE("slice runner: every slice runs once, on threads of their own") {
  ThreadSliceRunner runner;
  std::vector<std::atomic<int>> calls(4);
  std::vector<std::thread::id> ids(4);
  runner.run(4, [&](std::size_t i) {
    ++calls[i];
    ids[i] = std::this_thread::get_id();
  });
  for (const auto& c : calls)
    CHECK(c == 1);
  CHECK(ids[0] == std::this_thread::get_id());
  CHECK(ids[1] != ids[0]);
  runner.run(0, [](std::size_t) { FAIL("no slice to run"); });
}

TEST_CASE("slice runner: a slice's exception on another thread reaches the caller after all slices") {
  ThreadSliceRunner runner;
  std::atomic<int> finished = 0;
  CHECK_THROWS_AS(runner.run(3,
                             [&](std::size_t i) {
                               if (i == 1) throw std::bad_alloc();
                               std::this_thread::sleep_for(std::chrono::milliseconds(20));
                               ++finished;
                             }),
                  std::bad_alloc);
  CHECK(finished == 2);  // the slices that did not throw had all returned
  CHECK_THROWS_WITH(
      runner.run(2, [](std::size_t i) { throw std::runtime_error("slice " + std::to_string(i)); }),
      "slice 0");  // the first slice's, as when the slices run in turn
}
