#include <catch2/catch.hpp>

#include <chrono>
#include <random>
#include <span>
#include <string>
#include <vector>

#include <alsa/asoundlib.h>

#include "drivers/audio_front_end.hpp"
#include "tests/drivers/alsa_fifo.hpp"
#include "tests/test_util.hpp"

using namespace std::chrono_literals;
using gearpulse::AlsaCaptureConfig;
using gearpulse::AudioBlock;
using gearpulse::AudioFrontEnd;
using gearpulse::PcmFormat;
using gearpulse::test::TempDir;
using gearpulse::test::use_alsa_config;
using gearpulse::test::wait_for;
using gearpulse::test::write_raw;

namespace {

AlsaCaptureConfig capture_of(const std::string& device) {
  AlsaCaptureConfig c;
  c.device = device;
  c.format = PcmFormat::kS16;
  return c;
}

const AudioFrontEnd::Prepare kUsable = [](unsigned, const std::string&) { return std::string(); };

}  // namespace

TEST_CASE("audio: a device that will not open is retried with a delay that doubles up to 10 s") {
  TempDir dir;
  use_alsa_config(dir, "replay", dir / "in.raw");
  AudioFrontEnd audio(capture_of("no_such_pcm_gearpulse"), 1.0);
  int prepared = 0;
  const AudioFrontEnd::Prepare count = [&](unsigned, const std::string&) {
    ++prepared;
    return std::string();
  };
  auto now = std::chrono::steady_clock::now();
  std::vector<long long> delays;
  for (int i = 0; i < 7; ++i) {
    REQUIRE(audio.open_due(now));
    CHECK_FALSE(audio.open(now, count));
    delays.push_back(audio.retry_delay().count());
    CHECK_FALSE(audio.open_due(now + audio.retry_delay() - 1ms));
    now += audio.retry_delay();
  }
  CHECK(delays == std::vector<long long>{500, 1000, 2000, 4000, 8000, 10000, 10000});
  CHECK(prepared == 0);
  CHECK_FALSE(audio.is_open());
  CHECK(audio.error().find("cannot open") != std::string::npos);
  const auto status = audio.status();
  CHECK_FALSE(status.open);
  CHECK(status.error == audio.error());
}

TEST_CASE("audio: a stream the tracker cannot use is a failed open, and the next open reads timed blocks") {
  TempDir dir;
  std::vector<std::int16_t> src(20000);
  std::mt19937 rng(11);
  for (auto& s : src)
    s = static_cast<std::int16_t>(rng() & 0xFFFF);
  write_raw(dir / "in.raw", src);
  use_alsa_config(dir, "replay", dir / "in.raw");
  AudioFrontEnd audio(capture_of("replay"), 1.0);
  auto now = std::chrono::steady_clock::now();
  CHECK_FALSE(audio.open(now, [](unsigned rate, const std::string& describe) {
    return "no tracker at " + std::to_string(rate) + " Hz on " + describe;
  }));
  CHECK(audio.error().rfind("no tracker at 48000 Hz on ", 0) == 0);
  CHECK(audio.retry_delay() == 500ms);
  CHECK_FALSE(audio.is_open());

  now += audio.retry_delay();
  REQUIRE(audio.open(now, kUsable));
  CHECK(audio.is_open());
  CHECK(audio.error().empty());
  CHECK(audio.rate() == 48000);
  std::vector<float> block(1024);
  std::size_t frames = 0;
  int firsts = 0;
  double last_t0 = 0.0;
  bool ordered = true;
  std::uint64_t holes = 0;
  REQUIRE(wait_for(
      [&] {
        const AudioBlock b = audio.read(std::span<float>(block));
        frames += b.frames;
        if (b.timed) {
          firsts += b.first;
          ordered = ordered && (b.first || b.t0 > last_t0);
          last_t0 = b.t0;
          holes += b.hole;
        }
        return frames >= src.size();
      },
      20s));
  CHECK(firsts == 1);
  CHECK(ordered);
  CHECK(holes == 0);  // the ring holds the whole file: nothing is lost before it
  CHECK(audio.status().open);
  audio.close();
  CHECK_FALSE(audio.is_open());
  CHECK_FALSE(audio.status().open);
}

// libasound's own diagnostics reach stderr at log level trace only; the daemon says each failed open in
// one line of its own. A reload that changes the level changes which (they stayed off once turned off).
TEST_CASE("audio: libasound's diagnostics are shown at trace only, and follow a change of level") {
  TempDir dir;
  const auto path = dir / "stderr.txt";
  const auto stderr_of_a_failed_open = [&](bool show) {
    gearpulse::show_alsa_library_errors(show);
    std::fflush(stderr);
    const gearpulse::UniqueFd saved(::dup(STDERR_FILENO));
    {
      const gearpulse::UniqueFd to(::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600));
      ::dup2(to.get(), STDERR_FILENO);
    }
    snd_pcm_t* pcm = nullptr;
    if (::snd_pcm_open(&pcm, "gearpulse_test_no_such_pcm", SND_PCM_STREAM_CAPTURE, 0) == 0)
      ::snd_pcm_close(pcm);
    std::fflush(stderr);
    ::dup2(saved.get(), STDERR_FILENO);
    return gearpulse::test::read_text(path);
  };
  CHECK(stderr_of_a_failed_open(true).find("ALSA lib") != std::string::npos);
  CHECK(stderr_of_a_failed_open(false).empty());
  CHECK(stderr_of_a_failed_open(true).find("Unknown PCM gearpulse_test_no_such_pcm") != std::string::npos);
  gearpulse::show_alsa_library_errors(false);
}
