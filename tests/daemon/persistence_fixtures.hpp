#pragma once
// What the tests of the daemon's state files share: a model of three gears, training pairs, a full disk.
#include <catch2/catch.hpp>

#include <signal.h>
#include <sys/resource.h>

#include <cstddef>
#include <filesystem>

#include "core/gear_model.hpp"
#include "daemon/training_store.hpp"

namespace gearpulse::test {

inline std::size_t count_entries(const std::filesystem::path& dir) {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir))
    ++n;
  return n;
}

inline GearModel three_gears() {
  GearModel m;
  m.gears = {{0.05, 0.3, 0.001}, {0.09, 0.4, 0.001}, {0.14, 0.3, 0.002}};
  m.samples = 1000;
  m.sigma_speed = 0.3;
  m.sigma_freq = 0.5;
  return m;
}

// Training pair i: stamped i s after 1.7e9, at 0.1 i m/s and 20 + i Hz.
inline double pair_time(int i) {
  return 1.7e9 + i;
}

inline void add_pairs(daemon::TrainingStore& store, int from, int to) {
  for (int i = from; i < to; ++i)
    store.add({pair_time(i), 0.1 * i, 20.0 + i});
}

// Writes past `bytes` fail with EFBIG while it lives (SIGXFSZ ignored): a full disk for the writes of this
// process, which works for root too.
struct FileSizeLimit {
  rlimit old{};
  struct sigaction old_action {};
  explicit FileSizeLimit(rlim_t bytes) {
    struct sigaction ignore {};
    ignore.sa_handler = SIG_IGN;
    REQUIRE(::sigaction(SIGXFSZ, &ignore, &old_action) == 0);
    REQUIRE(::getrlimit(RLIMIT_FSIZE, &old) == 0);
    rlimit low = old;
    low.rlim_cur = bytes;
    REQUIRE(::setrlimit(RLIMIT_FSIZE, &low) == 0);
  }
  ~FileSizeLimit() {
    ::setrlimit(RLIMIT_FSIZE, &old);
    ::sigaction(SIGXFSZ, &old_action, nullptr);
  }
  FileSizeLimit(const FileSizeLimit&) = delete;
  FileSizeLimit& operator=(const FileSizeLimit&) = delete;
};

}  // namespace gearpulse::test
