#include <catch2/catch.hpp>

#include <fcntl.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <random>
#include <span>
#include <thread>
#include <vector>

#include "core/spsc_ring.hpp"
#include "drivers/alsa_capture.hpp"
#include "drivers/clock.hpp"
#include "tests/drivers/alsa_fifo.hpp"
#include "tests/test_util.hpp"

using namespace std::chrono_literals;
using gearpulse::AlsaCapture;
using gearpulse::AlsaCaptureConfig;
using gearpulse::PcmFormat;
using gearpulse::SpscRing;
using gearpulse::test::FifoFeeder;
using gearpulse::test::make_paced_pcm;
using gearpulse::test::TempDir;
using gearpulse::test::use_alsa_config;
using gearpulse::test::wait_for;
using gearpulse::test::write_raw;
using gearpulse::test::WriterBreak;

namespace {

// Reads `n` frames from the ring (waiting for them), as the tracker thread would.
std::vector<float> read_frames(SpscRing<float>& ring, std::size_t n) {
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
bool timestamps_increase(const AlsaCapture& cap, std::uint64_t first, std::uint64_t last) {
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

AlsaCaptureConfig paced_config(unsigned period) {
  AlsaCaptureConfig cfg;
  cfg.device = "paced";
  cfg.period_frames = period;
  return cfg;
}

// `periods` periods of distinct S16 values starting at `first` (where a frame came from is known).
std::vector<std::int16_t> numbered(unsigned period, std::size_t periods, int first = -32768) {
  std::vector<std::int16_t> src(period * periods);
  for (std::size_t i = 0; i < src.size(); ++i)
    src[i] = static_cast<std::int16_t>(first + static_cast<int>(i));
  return src;
}

float as_float(std::int16_t s) {
  return static_cast<float>(s) / 32768.0f;
}

// Frames of `got` (from `at` on) that differ from the S16 source they should be, converted.
std::size_t mismatches(const std::vector<float>& got, std::span<const std::int16_t> src, std::size_t at = 0) {
  std::size_t bad = 0;
  for (std::size_t i = 0; i < src.size(); ++i)
    bad += at + i >= got.size() || got[at + i] != as_float(src[i]);
  return bad;
}

}  // namespace

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

TEST_CASE("alsa: recovery is chosen by the error: overrun restarts, suspend resumes, a lost device reopens") {
  using gearpulse::AlsaRecovery;
  using gearpulse::recovery_for;
  CHECK(recovery_for(-EPIPE) == AlsaRecovery::kRestart);
  CHECK(recovery_for(-ESTRPIPE) == AlsaRecovery::kResume);
  CHECK(recovery_for(-ENODEV) == AlsaRecovery::kReopen);
  CHECK(recovery_for(-EBADFD) == AlsaRecovery::kReopen);  // the PCM is in no state to read
  CHECK(recovery_for(-EIO) == AlsaRecovery::kReopen);
  CHECK(recovery_for(-1) == AlsaRecovery::kReopen);  // a failure ALSA gives no name
  // A signal that interrupts the wait is no fault: nothing was lost and the device stays open.
  CHECK(recovery_for(-EINTR) == AlsaRecovery::kRetry);
  CHECK(recovery_for(-EAGAIN) == AlsaRecovery::kRetry);
  CHECK(std::string(gearpulse::to_string(recovery_for(-EPIPE))) == "restart");
}

// stats() reads the last failure from one atomic word: each step comes back with its own error, whatever
// the error's sign and size.
TEST_CASE("alsa: a failure held in one word comes back whole: its step and its negative error") {
  using gearpulse::AlsaFailure;
  using gearpulse::AlsaStep;
  for (int s = static_cast<int>(AlsaStep::kNone); s <= static_cast<int>(AlsaStep::kRead); ++s) {
    for (const int error : {0, -EIO, -EPIPE, -ENODEV, -1, std::numeric_limits<int>::min()}) {
      const AlsaFailure failure{static_cast<AlsaStep>(s), error};
      INFO("step " << gearpulse::to_string(failure.step) << ", error " << error);
      const AlsaFailure back = AlsaFailure::from_word(failure.word());
      CHECK(back.step == failure.step);
      CHECK(back.error == failure.error);
    }
  }
  CHECK(AlsaFailure{}.word() == 0);  // the atomic's initial value is "nothing failed"
  CHECK(AlsaFailure{AlsaStep::kRead, -EIO}.word() != AlsaFailure{AlsaStep::kWait, -EIO}.word());
}

// The file plugin's own answer to a writer that stalls: its read() on the FIFO blocks, so the capture
// is held up with the data; the null slave reports no XRUN. Frames arrive late, none is lost, and the
// sample clock, finding them a stall's length behind ALSA's timestamps, re-anchors forward.
TEST_CASE(
    "alsa: a stalled FIFO writer holds the capture up without loss and the clock re-anchors across it") {
  TempDir dir;
  const auto fifo = make_paced_pcm(dir);
  constexpr unsigned kPeriod = 480, kRate = 48000;
  const auto src = numbered(kPeriod, 100);  // 1 s
  constexpr auto kStall = 800ms;            // far beyond the 100 ms the clock takes as lateness
  FifoFeeder feeder(fifo, src, kPeriod, kRate, {WriterBreak::kStall, 40, kStall});
  SpscRing<float> ring(1 << 16);
  AlsaCapture cap(paced_config(kPeriod), ring);
  cap.start();
  feeder.go();
  const auto got = read_frames(ring, src.size());
  REQUIRE(got.size() == src.size());
  CHECK(mismatches(got, src) == 0);
  const auto st = cap.stats();
  CHECK(st.dropped == 0);
  CHECK(st.xruns == 0);  // the null slave never overruns: a stall is not an XRUN here
  CHECK(st.running);
  CHECK(st.streaming);
  CHECK(st.clock_resets >= 1);
  CHECK(timestamps_increase(cap, 0, src.size() - 1));
  // The stall shows in the timestamps: the span exceeds the frames' duration by most of it (a slower
  // machine only adds to it).
  std::int64_t t0 = 0, t1 = 0;
  REQUIRE(cap.frame_time(0, t0));
  REQUIRE(cap.frame_time(src.size() - 1, t1));
  const double excess = static_cast<double>(t1 - t0) - (src.size() - 1) * 1e9 / kRate;
  CHECK(excess >= 0.5 * std::chrono::duration<double, std::nano>(kStall).count());
  cap.stop();
}

// The file plugin's answer to a writer that goes away: read() returns end of file and the plugin
// returns the period anyway, without touching the buffer, at once and without end. The capture must
// not spin on that (it holds such a source to the clock), must keep the device open, and must carry
// the writer's frames again, bit-exact, once a writer is back.
TEST_CASE(
    "alsa: a FIFO writer that goes away and comes back: no spin meanwhile and its frames come through "
    "again") {
  TempDir dir;
  const auto fifo = make_paced_pcm(dir);
  constexpr unsigned kPeriod = 480, kRate = 48000;
  constexpr std::size_t kBefore = 30, kAfter = 30;
  const auto src = numbered(kPeriod, kBefore + kAfter);  // values after the gap differ from all before it
  FifoFeeder feeder(fifo, src, kPeriod, kRate, {WriterBreak::kClose, kBefore, 1500ms});
  SpscRing<float> ring(1 << 18);
  AlsaCapture cap(paced_config(kPeriod), ring);
  const std::int64_t start = gearpulse::monotonic_ns();
  cap.start();
  feeder.go();
  std::vector<float> got;
  const float last = as_float(src.back());
  std::uint64_t most_ahead = 0;  // frames captured beyond real time, worst seen
  REQUIRE(wait_for(
      [&] {
        float buf[8192];
        for (std::size_t n; (n = ring.read_bulk(buf)) > 0;)
          got.insert(got.end(), buf, buf + n);
        const double elapsed_s = static_cast<double>(gearpulse::monotonic_ns() - start) / 1e9;
        const double ahead = static_cast<double>(cap.stats().frames) - elapsed_s * kRate;
        most_ahead = std::max(most_ahead, static_cast<std::uint64_t>(std::max(0.0, ahead)));
        return !got.empty() && std::find(got.begin(), got.end(), last) != got.end();
      },
      30s));
  const auto st = cap.stats();
  cap.stop();
  // Before the gap: the writer's frames in order.
  REQUIRE(got.size() >= src.size());
  const std::span<const std::int16_t> before(src.data(), kBefore * kPeriod),
      after(src.data() + before.size(), kAfter * kPeriod);
  CHECK(mismatches(got, before) == 0);
  // After it: all of the new writer's frames, contiguous and bit-exact.
  const auto resumed =
      std::find(got.begin() + static_cast<long>(before.size()), got.end(), as_float(after[0]));
  REQUIRE(resumed != got.end());
  CHECK(mismatches(got, after, static_cast<std::size_t>(resumed - got.begin())) == 0);
  // In between, stale periods, repeats of the last one, not pushed; held to about a second ahead of
  // real time (the bound allows for where the clock was anchored): a spinning capture would be
  // millions of frames ahead.
  CHECK(resumed - got.begin() == static_cast<long>(before.size()));
  CHECK(st.repeated > 0);
  CHECK(most_ahead <= 3 * kRate / 2);
  CHECK(st.reopens == 0);
  CHECK(st.xruns == 0);
  CHECK(st.dropped == 0);
  CHECK(st.running);
  CHECK(st.streaming);  // the device stayed open throughout
  CHECK(timestamps_increase(cap, 0, got.size() - 1));
}

// A device that fails under the capture (a USB card pulled out) and is back later. The file plugin writes
// what it captures to its `file`; here a symbolic link to /dev/full, so its flush fails and snd_pcm_readi
// returns -EIO, as a card that has gone does. Then the infile is removed (every reopen fails and the
// backoff grows), then a new infile is put in place and the link turned to /dev/null (the reopen
// succeeds). The capture closes the failed PCM, says it is not streaming, keeps trying and carries the
// new device's frames bit-exact once it opens.
TEST_CASE("alsa: a device lost while capturing is closed and reopened, and its frames come through again") {
  TempDir dir;
  constexpr unsigned kPeriod = 480;
  const auto infile = dir / "in.raw", sink = dir / "out";
  write_raw(infile, numbered(kPeriod, 20));
  std::filesystem::create_symlink("/dev/full", sink);
  use_alsa_config(dir, "unplugged", infile, sink);
  AlsaCaptureConfig cfg;
  cfg.device = "unplugged";
  cfg.period_frames = kPeriod;
  cfg.reopen_min = 20ms;
  cfg.reopen_max = 200ms;
  cfg.realtime = true;  // at the lowest FIFO priority, where it is granted
  cfg.rt_priority = 1;
  SpscRing<float> ring(1 << 16);
  AlsaCapture cap(cfg, ring);
  std::vector<float> got;
  const auto drain = [&] {
    float buf[8192];
    for (std::size_t n; (n = ring.read_bulk(buf)) > 0;)
      got.insert(got.end(), buf, buf + n);
  };
  cap.start();
  // Failing: each open reads a little, then the read fails and the PCM is closed and opened again.
  REQUIRE(wait_for(
      [&] {
        drain();
        const auto s = cap.stats();
        return s.reopens >= 2 && s.last_error == -EIO && s.failed_step == gearpulse::AlsaStep::kRead;
      },
      10s));
  // Gone: no device to open. Each attempt is counted and timed, and fails at the open.
  const double gone_at = gearpulse::wall_now();
  std::filesystem::remove(infile);
  REQUIRE(wait_for(
      [&] {
        drain();
        const auto s = cap.stats();
        return s.last_error == -ENOENT && s.last_attempt > gone_at;
      },
      10s));
  const auto lost = cap.stats();
  CHECK_FALSE(lost.streaming);
  CHECK(lost.running);
  CHECK(lost.failed_step == gearpulse::AlsaStep::kOpen);
  CHECK(std::string(gearpulse::to_string(lost.failed_step)) == "open");
  CHECK(lost.open_attempts >= 1);
  CHECK(lost.last_attempt <= gearpulse::wall_now());
  REQUIRE(wait_for(
      [&] {
        drain();
        const auto s = cap.stats();
        return s.open_attempts > lost.open_attempts && s.last_attempt > lost.last_attempt;
      },
      10s));
  // Reopening is no real-time work: the thread leaves SCHED_FIFO for it and takes it back once the device
  // is open again.
  if (!lost.realtime_ok) WARN("SCHED_FIFO not granted here: the capture thread's policy is not checked");
  CHECK_FALSE(lost.fifo);
  // Back, with other frames (the sink mended first: no open finds the new infile with the old sink).
  std::filesystem::remove(sink);
  std::filesystem::create_symlink("/dev/null", sink);
  const auto back = numbered(kPeriod, 40, 0);
  write_raw(dir / "next.raw", back);
  std::filesystem::rename(dir / "next.raw", infile);
  REQUIRE(wait_for(
      [&] {
        drain();
        return !got.empty() && got.back() == as_float(back.back());
      },
      10s));
  const auto st = cap.stats();
  cap.stop();
  const auto resumed = std::find(got.begin(), got.end(), as_float(back.front()));
  REQUIRE(resumed != got.end());
  CHECK(got.end() - resumed == static_cast<long>(back.size()));
  CHECK(mismatches(got, back, static_cast<std::size_t>(resumed - got.begin())) == 0);
  CHECK(st.streaming);
  CHECK(st.fifo == st.realtime_ok);
  CHECK(st.reopens > lost.reopens);
  CHECK(st.dropped == 0);
  CHECK(timestamps_increase(cap, 0, got.size() - 1));
}

// A source that holds its stream open and sends nothing (a card whose pointer stopped) is said to be
// stalled once 2 s pass without a frame, and no longer once frames come again.
TEST_CASE("alsa: an open device that delivers nothing for seconds is stalled, until frames come again") {
  TempDir dir;
  const auto fifo = make_paced_pcm(dir);
  constexpr unsigned kPeriod = 480, kRate = 48000;
  const auto src = numbered(kPeriod, 200);  // 2 s
  // 6 s without frames: stalled for the last 4 of them, time for a loaded machine to look.
  FifoFeeder feeder(fifo, src, kPeriod, kRate, {WriterBreak::kStall, 50, 6000ms});
  SpscRing<float> ring(1 << 18);
  AlsaCapture cap(paced_config(kPeriod), ring);
  cap.start();
  feeder.go();
  CHECK_FALSE(cap.stats().stalled);
  REQUIRE(wait_for([&] { return cap.stats().stalled; }, 10s));
  CHECK(cap.stats().silent_s > 2.0);
  CHECK(cap.stats().streaming);
  const auto got = read_frames(ring, src.size());
  REQUIRE(got.size() == src.size());
  CHECK_FALSE(cap.stats().stalled);
  cap.stop();
}

TEST_CASE("alsa: a period that repeats the one before is not pushed, and the capture says it is frozen") {
  TempDir dir;
  constexpr unsigned kPeriod = 480;
  // Ten distinct periods, one period of digital silence repeated twenty times, ten distinct periods;
  // then the file ends, and the file plugin hands back its last period for ever.
  const auto first = numbered(kPeriod, 10);
  const std::vector<std::int16_t> silence(kPeriod, 0);
  const auto last = numbered(kPeriod, 10, 1000);
  std::vector<std::int16_t> src(first);
  for (int i = 0; i < 20; ++i)
    src.insert(src.end(), silence.begin(), silence.end());
  src.insert(src.end(), last.begin(), last.end());
  write_raw(dir / "in.raw", src);
  use_alsa_config(dir, "replay", dir / "in.raw");
  SpscRing<float> ring(1 << 16);
  AlsaCaptureConfig cfg;
  cfg.device = "replay";
  cfg.period_frames = kPeriod;
  AlsaCapture cap(cfg, ring);
  cap.start();
  std::vector<float> got = read_frames(ring, first.size() + silence.size() + last.size());
  // Once the file has ended, nothing more comes through, and the capture says why.
  REQUIRE(wait_for([&] { return cap.stats().frozen; }, 10s));
  std::this_thread::sleep_for(200ms);
  float extra[4096];
  const std::size_t more = ring.read_bulk(extra);
  const auto st = cap.stats();
  cap.stop();
  CHECK(more == 0);
  CHECK(mismatches(got, first) == 0);
  CHECK(mismatches(got, silence, first.size()) == 0);  // the first silent period, once
  CHECK(mismatches(got, last, first.size() + silence.size()) == 0);
  CHECK(st.repeated >= 19 * kPeriod + kPeriod);  // the silence's repeats and the stale periods after the end
  CHECK(st.frames >= src.size());
  CHECK(st.dropped == 0);
  CHECK(timestamps_increase(cap, 0, got.size() - 1));
}
