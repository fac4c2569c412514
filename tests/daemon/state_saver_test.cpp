// The training store's periodic writes run on a thread of their own: when a save or journal append is
// due, what follows a failed save, a new interval taking effect during a wait, and a write that stalls
// (a failing SD card) holding up neither the thread that asks for status nor the one that changes the
// interval.
#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <future>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "daemon/state_saver.hpp"
#include "tests/test_util.hpp"

using gearpulse::daemon::StateSaver;
using gearpulse::test::wait_for;
using namespace std::chrono_literals;

namespace {

// The writes the saver made, in order: "save", "journal".
struct WriteLog {
  std::mutex mutex;
  std::vector<std::string> writes;
  std::atomic<bool> unsaved{true};
  std::atomic<bool> save_works{true};

  void add(const char* what) {
    std::lock_guard lock(mutex);
    writes.emplace_back(what);
  }
  std::vector<std::string> copy() {
    std::lock_guard lock(mutex);
    return writes;
  }
  StateSaver::Writes hooks() {
    return {.unsaved = [this] { return unsaved.load(); },
            .save =
                [this] {
                  add("save");
                  return save_works.load();
                },
            .journal = [this] { add("journal"); }};
  }
};

std::size_t count(const std::vector<std::string>& writes, const std::string& what) {
  return static_cast<std::size_t>(std::count(writes.begin(), writes.end(), what));
}

}  // namespace

TEST_CASE("state saver: saves what is unsaved, journals between saves and after a failed save") {
  WriteLog log;
  StateSaver saver(log.hooks(), 0.3s, 0.05s);

  SECTION("a store holding new pairs is saved every save interval, journaled between saves") {
    saver.start();
    REQUIRE(wait_for([&] { return count(log.copy(), "save") >= 2; }, 10s));
    saver.stop();
    const auto writes = log.copy();
    CHECK(count(writes, "journal") >= 2);
  }
  SECTION("a save that works is not followed by a journal append: the file holds the pairs") {
    StateSaver fast(log.hooks(), 0.02s, 3600s);
    fast.start();
    REQUIRE(wait_for([&] { return count(log.copy(), "save") >= 3; }, 10s));
    fast.stop();
    CHECK(count(log.copy(), "journal") == 0);
  }
  SECTION("a store its file holds already is not saved again; the journal appends go on") {
    log.unsaved = false;
    saver.start();
    REQUIRE(wait_for([&] { return count(log.copy(), "journal") >= 10; }, 10s));
    saver.stop();
    CHECK(count(log.copy(), "save") == 0);
  }
  SECTION(
      "a save that fails is followed by a journal append, so the pairs are kept however short the "
      "interval") {
    log.save_works = false;
    StateSaver fast(log.hooks(), 0.02s, 3600s);  // saves due far more often than journal appends
    fast.start();
    REQUIRE(wait_for([&] { return count(log.copy(), "save") >= 3; }, 10s));
    fast.stop();
    const auto writes = log.copy();
    for (std::size_t i = 0; i + 1 < writes.size(); ++i)
      if (writes[i] == "save") CHECK(writes[i + 1] == "journal");
  }
}

TEST_CASE("state saver: a new save interval ends a wait under way") {
  WriteLog log;
  StateSaver saver(log.hooks(), 3600s, 3600s);
  saver.start();
  std::this_thread::sleep_for(100ms);
  CHECK(log.copy().empty());
  saver.set_save_interval(0.05s);
  CHECK(wait_for([&] { return count(log.copy(), "save") >= 1; }, 10s));
  saver.stop();
}

TEST_CASE("state saver: a stalled write holds up neither status nor a reload, and is said while it lasts") {
  std::promise<void> release;
  const std::shared_future<void> released = release.get_future().share();
  std::atomic<bool> writing{false};
  StateSaver saver({.unsaved = [] { return true; },
                    .save =
                        [&] {
                          writing = true;
                          released.wait();  // an fsync that does not return
                          return true;
                        },
                    .journal = [] {}},
                   0.02s, 3600s);
  CHECK(saver.busy_for() == StateSaver::Seconds(0.0));
  saver.start();
  REQUIRE(wait_for([&] { return writing.load(); }, 10s));
  std::this_thread::sleep_for(300ms);
  const auto asked = std::chrono::steady_clock::now();
  const auto busy = saver.busy_for();
  saver.set_save_interval(0.5s);
  const auto answered = std::chrono::steady_clock::now() - asked;
  CHECK(busy >= 250ms);
  CHECK(answered < 2s);  // neither waited for the write (which would be for good)
  release.set_value();
  CHECK(wait_for([&] { return saver.busy_for() < 250ms; }, 10s));
  saver.stop();
}
