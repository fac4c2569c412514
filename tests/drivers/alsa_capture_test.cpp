// ALSA capture of a working source: formats, the sample clock, an overrun ring, a bad name, pacing.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <thread>
#include <vector>

#include "core/spsc_ring.hpp"
#include "drivers/alsa_capture.hpp"
#include "drivers/clock.hpp"
#include "tests/drivers/alsa_fifo.hpp"
#include "tests/drivers/alsa_frames.hpp"
#include "tests/test_util.hpp"

using namespace std::chrono_literals;
using gearpulse::AlsaCapture;
using gearpulse::AlsaCaptureConfig;
using gearpulse::PcmFormat;
using gearpulse::SpscRing;
using gearpulse::test::as_float;
using gearpulse::test::FifoFeeder;
using gearpulse::test::make_paced_pcm;
using gearpulse::test::mismatches;
using gearpulse::test::numbered;
using gearpulse::test::paced_config;
using gearpulse::test::read_frames;
using gearpulse::test::TempDir;
using gearpulse::test::timestamps_increase;
using gearpulse::test::use_alsa_config;
using gearpulse::test::wait_for;
using gearpulse::test::write_raw;

TEST_CASE("alsa: unpaced S16 mono frames arrive bit-exact with increasing timestamps") {
  TempDir dir;
  std::vector<std::int16_t> src(40000);
  std::mt19937 rng(7);
  for (auto& s : src)
    s = static_cast<std::int16_t>(rng() & 0xFFFF);
  write_raw(dir / "in.raw", src);
  use_alsa_config(dir, "replay", dir / "in.raw");
  SpscRing<float> ring(1 << 16);
  AlsaCaptureConfig cfg;
  cfg.device = "replay";
  cfg.format = PcmFormat::kS16;
  AlsaCapture cap(cfg, ring);
  CHECK(cap.rate() == 48000);
  CHECK(cap.channels() == 1);
  CHECK(cap.format() == PcmFormat::kS16);
  std::int64_t t = 0;
  CHECK_FALSE(cap.frame_time(0, t));  // nothing captured yet
  cap.start();
  const auto got = read_frames(ring, src.size());
  REQUIRE(got.size() == src.size());
  CHECK(mismatches(got, src) == 0);
  CHECK(timestamps_increase(cap, 0, src.size() - 1));
  CHECK(cap.stats().streaming);
  cap.stop();
  const auto st = cap.stats();
  CHECK(st.frames >= src.size());
  CHECK_FALSE(st.running);
  CHECK_FALSE(st.streaming);
}

TEST_CASE("alsa: S32 and FLOAT stereo are converted per channel or mixed") {
  TempDir dir;
  std::vector<std::int32_t> s32(2 * 8192);
  std::vector<float> f32(2 * 8192);
  std::mt19937 rng(11);
  for (auto& s : s32)
    s = static_cast<std::int32_t>(rng());
  std::uniform_real_distribution<float> u(-1, 1);
  for (auto& s : f32)
    s = u(rng);
  write_raw(dir / "s32.raw", s32);
  write_raw(dir / "f32.raw", f32);
  use_alsa_config(dir, "s32", dir / "s32.raw");
  use_alsa_config(dir, "f32", dir / "f32.raw");
  {
    SpscRing<float> ring(1 << 15);
    AlsaCaptureConfig cfg;
    cfg.device = "s32";
    cfg.format = PcmFormat::kS32;
    cfg.channels = 2;
    cfg.channel = 1;  // the right channel only
    AlsaCapture cap(cfg, ring);
    REQUIRE(cap.format() == PcmFormat::kS32);
    REQUIRE(cap.channels() == 2);
    cap.start();
    const auto got = read_frames(ring, 8192);
    cap.stop();
    REQUIRE(got.size() == 8192);
    std::size_t bad = 0;
    for (std::size_t i = 0; i < got.size(); ++i)
      bad += got[i] != static_cast<float>(static_cast<double>(s32[2 * i + 1]) / 2147483648.0);
    CHECK(bad == 0);
  }
  {
    SpscRing<float> ring(1 << 15);
    AlsaCaptureConfig cfg;
    cfg.device = "f32";
    cfg.format = PcmFormat::kFloat;
    cfg.channels = 2;
    cfg.channel = -1;  // mean of both
    AlsaCapture cap(cfg, ring);
    REQUIRE(cap.format() == PcmFormat::kFloat);
    cap.start();
    const auto got = read_frames(ring, 8192);
    cap.stop();
    REQUIRE(got.size() == 8192);
    std::size_t bad = 0;
    for (std::size_t i = 0; i < got.size(); ++i)
      bad += got[i] != (0.0f + f32[2 * i] + f32[2 * i + 1]) / 2.0f;
    CHECK(bad == 0);
  }
}

TEST_CASE("alsa: FIFO-paced capture is bit-exact and its sample clock runs at the rate") {
  TempDir dir;
  const auto fifo = make_paced_pcm(dir);
  constexpr unsigned kPeriod = 480, kRate = 48000;  // 10 ms periods
  const auto src = numbered(kPeriod, 60);           // 0.6 s
  FifoFeeder feeder(fifo, src, kPeriod, kRate);
  SpscRing<float> ring(1 << 16);
  AlsaCapture cap(paced_config(kPeriod), ring);
  REQUIRE(cap.period_frames() == kPeriod);
  cap.start();
  feeder.go();
  const auto got = read_frames(ring, src.size());
  REQUIRE(got.size() == src.size());
  CHECK(mismatches(got, src) == 0);
  CHECK(timestamps_increase(cap, 0, src.size() - 1));
  // The sample clock follows the frames' arrival only within its correction bounds: rate within 500 ppm,
  // offset steps of at most period / 8 per quarter second. Over 0.6 s that is under 0.5 % of the span,
  // however late a loaded machine delivers the periods.
  std::int64_t t0 = 0, t1 = 0;
  REQUIRE(cap.frame_time(0, t0));
  REQUIRE(cap.frame_time(src.size() - 1, t1));
  const double nominal = (src.size() - 1) * 1e9 / kRate;
  if (cap.stats().clock_resets == 0) {
    CHECK(static_cast<double>(t1 - t0) == Approx(nominal).epsilon(5e-3));
  } else {
    WARN("periods arrived over 100 ms late (machine overloaded): the clock re-anchored, span not checked");
  }
  cap.stop();
  CHECK(cap.stats().dropped == 0);
}

TEST_CASE("alsa: a stalled consumer overruns the ring and the stream recovers with a time jump") {
  TempDir dir;
  const auto fifo = make_paced_pcm(dir);
  constexpr unsigned kPeriod = 480, kRate = 48000;
  const auto src = numbered(kPeriod, 50);  // unique values: where a frame came from is known
  FifoFeeder feeder(fifo, src, kPeriod, kRate);
  SpscRing<float> ring(2048);  // ~43 ms
  AlsaCapture cap(paced_config(kPeriod), ring);
  cap.start();
  feeder.go();
  // The consumer stalls until the capture had to drop a few periods.
  REQUIRE(wait_for([&] { return cap.stats().dropped >= 4 * kPeriod; }, 10s));
  CHECK(ring.take_overrun());
  const auto dropped_in_stall = cap.stats().dropped;
  // It catches up and reads to the end of the source.
  std::vector<float> got;
  const float last = as_float(src.back());
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (std::find(got.begin(), got.end(), last) == got.end() &&
         std::chrono::steady_clock::now() < deadline) {
    float buf[4096];
    const std::size_t n = ring.read_bulk(buf);
    got.insert(got.end(), buf, buf + n);
    if (n == 0) std::this_thread::sleep_for(2ms);
  }
  const auto st = cap.stats();
  cap.stop();
  const auto end = std::find(got.begin(), got.end(), last);
  REQUIRE(end != got.end());
  got.erase(end + 1, got.end());  // the silence that follows the source
  CHECK(st.dropped >= 4 * kPeriod);
  // The stream is the source with holes: the first is the stall provoked above (a busy machine may
  // add more). Every frame between holes follows its predecessor in the source, the frames skipped
  // add up to the drop count, and timestamps jump across each hole by the skipped frames' duration.
  auto source_index = [](float v) { return static_cast<long>(std::lround(v * 32768.0f)) + 32768; };
  REQUIRE(got.size() > 2048);
  CHECK(source_index(got[0]) == 0);
  std::size_t holes = 0;
  long skipped_total = 0;
  std::size_t bad_backwards = 0, bad_jumps = 0;
  for (std::size_t i = 1; i < got.size(); ++i) {
    const long skipped = source_index(got[i]) - source_index(got[i - 1]) - 1;
    if (skipped == 0) continue;
    if (skipped < 0) {
      ++bad_backwards;
      continue;
    }
    ++holes;
    skipped_total += skipped;
    std::int64_t before = 0, after = 0;
    const bool known = cap.frame_time(i - 1, before) && cap.frame_time(i, after);
    const double want = (skipped + 1) * 1e9 / kRate;
    if (!known || std::fabs(static_cast<double>(after - before) - want) > 1e-3 * want) {
      std::printf("hole at %zu: %ld frames skipped, time step %ld ns, want %.0f\n", i, skipped,
                  static_cast<long>(after - before), want);
      ++bad_jumps;
    }
  }
  CHECK(holes >= 1);
  CHECK(bad_backwards == 0);
  CHECK(bad_jumps == 0);
  // Drops after the last source frame (silence) may be counted too, never fewer than the holes show.
  CHECK(skipped_total >= static_cast<long>(dropped_in_stall));
  CHECK(skipped_total <= static_cast<long>(st.dropped));
  CHECK(timestamps_increase(cap, 0, got.size() - 1));
}

TEST_CASE("alsa: an unknown PCM name is a clear error") {
  TempDir dir;
  use_alsa_config(dir, "replay", dir / "in.raw");
  SpscRing<float> ring(1024);
  AlsaCaptureConfig cfg;
  cfg.device = "no_such_pcm_gearpulse";
  CHECK_THROWS_WITH(AlsaCapture(cfg, ring),
                    Catch::Contains("no_such_pcm_gearpulse") && Catch::Contains("cannot open"));
  // The step and the code, for status.
  try {
    AlsaCapture cap(cfg, ring);
    FAIL("opened a PCM that does not exist");
  } catch (const gearpulse::AlsaOpenError& e) {
    CHECK(e.step() == gearpulse::AlsaStep::kOpen);
    CHECK(e.error() < 0);
  }
}

TEST_CASE("alsa: a source faster than real time is held to the clock instead of spinning") {
  TempDir dir;
  std::vector<std::int16_t> src(48000 * 10, 0);  // 10 s of audio, read unpaced by the file plugin
  write_raw(dir / "in.raw", src);
  use_alsa_config(dir, "replay", dir / "in.raw");
  SpscRing<float> ring(1 << 20);
  AlsaCaptureConfig cfg;
  cfg.device = "replay";
  AlsaCapture cap(cfg, ring);
  const std::int64_t start = gearpulse::monotonic_ns();
  cap.start();
  REQUIRE(wait_for([&] { return cap.stats().frames >= 48000; }, 10s));
  std::this_thread::sleep_for(300ms);
  const auto frames = cap.stats().frames;
  const double elapsed_s = static_cast<double>(gearpulse::monotonic_ns() - start) / 1e9;
  cap.stop();
  // At most one second ahead of real time (plus a period); unthrottled it would be all 10 s at once.
  CHECK(static_cast<double>(frames) <= (elapsed_s + 1.0) * 48000 + cap.period_frames());
}
