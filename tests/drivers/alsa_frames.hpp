#pragma once
// The frames a capture test reads back: numbered S16 sources, the frames that differ, the timestamps.
#include <catch2/catch.hpp>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <span>
#include <vector>

#include "core/spsc_ring.hpp"
#include "drivers/alsa_capture.hpp"
#include "tests/test_util.hpp"

namespace gearpulse::test {

// Reads `n` frames from the ring (waiting for them), as the tracker thread would.
inline std::vector<float> read_frames(SpscRing<float>& ring, std::size_t n) {
  using namespace std::chrono_literals;
  std::vector<float> out(n);
  std::size_t got = 0;
  wait_for(
      [&] {
        got += ring.read_bulk(std::span<float>(out.data() + got, n - got));
        return got == n;
      },
      20s);
  out.resize(got);
  return out;
}

// Every frame's timestamp is later than the previous one's.
inline bool timestamps_increase(const AlsaCapture& cap, std::uint64_t first, std::uint64_t last) {
  std::int64_t prev = 0;
  if (!cap.frame_time(first, prev)) return false;
  for (std::uint64_t i = first + 1; i <= last; ++i) {
    std::int64_t t = 0;
    if (!cap.frame_time(i, t) || t <= prev) {
      std::printf("frame %lu: t %ld after %ld\n", static_cast<unsigned long>(i), static_cast<long>(t),
                  static_cast<long>(prev));
      return false;
    }
    prev = t;
  }
  return true;
}

inline AlsaCaptureConfig paced_config(unsigned period) {
  AlsaCaptureConfig cfg;
  cfg.device = "paced";
  cfg.period_frames = period;
  return cfg;
}

// `periods` periods of distinct S16 values starting at `first` (where a frame came from is known).
inline std::vector<std::int16_t> numbered(unsigned period, std::size_t periods, int first = -32768) {
  std::vector<std::int16_t> src(period * periods);
  for (std::size_t i = 0; i < src.size(); ++i)
    src[i] = static_cast<std::int16_t>(first + static_cast<int>(i));
  return src;
}

inline float as_float(std::int16_t s) {
  return static_cast<float>(s) / 32768.0f;
}

// Frames of `got` (from `at` on) that differ from the S16 source they should be, converted.
inline std::size_t mismatches(const std::vector<float>& got, std::span<const std::int16_t> src,
                              std::size_t at = 0) {
  std::size_t bad = 0;
  for (std::size_t i = 0; i < src.size(); ++i)
    bad += at + i >= got.size() || got[at + i] != as_float(src[i]);
  return bad;
}

}  // namespace gearpulse::test
