// `gearpulse-devtools feed`: plays a raw PCM file into a FIFO at real-time pace, one ALSA period per write.
//
// The ALSA `file` plugin, used as a capture PCM with a FIFO as its `infile`, reads one period per
// transfer; a write of any other size leaves holes in the captured stream. So every write here is
// exactly one period, and the writes are paced from one fixed start with clock_nanosleep(TIMER_ABSTIME)
// so the stream never drifts from the wall clock however long it runs.
//
// A sound card holds at most its ALSA buffer, whose frames the capture's time stamps count; a FIFO holds
// what the plugin has not read yet unseen by ALSA. So the FIFO is shrunk to the kernel's smallest, one
// page, when a period fits in PIPE_BUF (4096 bytes; mono s16 at 1024 frames is 2048): a write of at
// most PIPE_BUF bytes is atomic, so a small pipe never splits a period. A larger period keeps the
// default size: the kernel rounds a pipe's size up to a power of two of pages, and a period that fills
// one only in part could be written in two pieces, the plugin reading the first as a whole period. With
// --wait-start nothing is written before SIGUSR1, so that a capture opened early reads the first period
// the moment it is written: the audio then reaches the capture as it would from a card. Written at once
// on open instead, the periods played before the capture's first read (the daemon's start-up) wait in
// the FIFO: read all at once, they set the capture's sample clock ahead of real time, which then holds
// the stream back (AlsaCapture's hold_to_clock), and the audio reached gearpulsed 1.5 s after its drive
// time for the whole drive (bench/daemon_outages.sh).
#include <fcntl.h>
#include <limits.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "drivers/unique_fd.hpp"
#include "tools/gearpulse/commands.hpp"

namespace gearpulse::cli {
namespace {

struct FeedOptions {
  std::string input;
  std::string fifo;
  int period = 1024;  // frames per write
  int rate = 48000;   // frames per second
  int channels = 1;
  std::string format = "s16";
  bool quiet = false;
  bool wait_start = false;  // write nothing before SIGUSR1 (the FIFO opened first)
};

int bytes_per_sample(const std::string& format) {
  if (format == "s16") return 2;
  if (format == "s32" || format == "float") return 4;
  throw UsageError("--format must be s16, s32 or float, not '" + format + "'");
}

std::vector<std::uint8_t> read_whole_file(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw UsageError(path + ": is a directory");
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) throw UsageError(path + ": " + std::strerror(errno));
  std::vector<std::uint8_t> data;
  std::uint8_t buf[1 << 16];
  std::size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0)
    data.insert(data.end(), buf, buf + n);
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed) throw UsageError(path + ": read error");
  return data;
}

void add_ns(timespec& ts, std::int64_t ns) {
  const std::int64_t total = ts.tv_nsec + ns;
  ts.tv_sec += static_cast<time_t>(total / 1'000'000'000);
  ts.tv_nsec = static_cast<long>(total % 1'000'000'000);
}

// Writes all of buf, resuming after signals; false when the reader went away.
bool write_all(int fd, const std::uint8_t* buf, std::size_t len) {
  while (len > 0) {
    const ssize_t n = ::write(fd, buf, len);
    if (n < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    buf += n;
    len -= static_cast<std::size_t>(n);
  }
  return true;
}

int run_feed(const FeedOptions& o) {
  // Blocked first, before the file is read and the FIFO opened, so a SIGUSR1 sent meanwhile waits for
  // sigwait instead of ending the process.
  sigset_t start_signal;
  sigemptyset(&start_signal);
  sigaddset(&start_signal, SIGUSR1);
  if (o.wait_start && ::sigprocmask(SIG_BLOCK, &start_signal, nullptr) != 0)
    throw std::runtime_error(std::string("cannot block SIGUSR1: ") + std::strerror(errno));
  // ALSA's own limits: at most 1024 channels; a period of at most a few seconds of audio.
  const auto within = [](const char* name, long long v, long long hi) {
    if (v < 1 || v > hi)
      throw UsageError(std::string(name) + " " + std::to_string(v) + " is out of range (1.." +
                       std::to_string(hi) + ")");
  };
  within("--period", o.period, 1 << 24);
  within("--rate", o.rate, 768000);
  within("--channels", o.channels, 1024);
  const std::size_t frame_bytes = static_cast<std::size_t>(o.channels * bytes_per_sample(o.format));
  const std::size_t period_bytes = frame_bytes * static_cast<std::size_t>(o.period);
  std::vector<std::uint8_t> data = read_whole_file(o.input);
  if (data.size() % frame_bytes != 0) {
    throw UsageError(o.input + ": size " + std::to_string(data.size()) + " is not a whole number of " +
                     std::to_string(frame_bytes) + "-byte frames");
  }
  // The plugin only ever reads whole periods: pad the tail with silence rather than leave it unread.
  const std::size_t periods = (data.size() + period_bytes - 1) / period_bytes;
  data.resize(periods * period_bytes, 0);

  std::signal(SIGPIPE, SIG_IGN);
  const gearpulse::UniqueFd fifo(::open(o.fifo.c_str(), O_WRONLY));  // blocks until the capture side opens it
  if (!fifo) throw UsageError(o.fifo + ": " + std::strerror(errno));
  const int fd = fifo.get();
  // One page (the kernel's smallest pipe) when a period's write is atomic; see the top of this file.
  if (period_bytes <= PIPE_BUF && ::fcntl(fd, F_SETPIPE_SZ, static_cast<int>(period_bytes)) < 0) {
    std::fprintf(stderr,
                 "gearpulse-devtools feed: %s: cannot shrink the FIFO (%s): unread audio may pile up\n",
                 o.fifo.c_str(), std::strerror(errno));
  }
  if (o.wait_start) {
    // Said once the FIFO is open and shrunk: a caller may wait for this line before it signals.
    std::fprintf(stderr, "gearpulse-devtools feed: %s: FIFO open, waiting for SIGUSR1\n", o.fifo.c_str());
    int got = 0;
    while (::sigwait(&start_signal, &got) != 0) {
    }
  }

  timespec start{};
  clock_gettime(CLOCK_MONOTONIC, &start);
  const double period_ns = 1e9 * o.period / o.rate;
  std::size_t written = 0;
  for (; written < periods; ++written) {
    if (!write_all(fd, data.data() + written * period_bytes, period_bytes)) break;
    // Deadline of the next write, from the fixed start: rounding never accumulates.
    timespec next = start;
    add_ns(next, static_cast<std::int64_t>(period_ns * static_cast<double>(written + 1)));
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr) == EINTR) {
    }
  }
  if (written < periods) {
    std::fprintf(stderr, "gearpulse-devtools feed: %s: reader closed after %zu of %zu periods\n",
                 o.fifo.c_str(), written, periods);
    return 1;
  }
  if (!o.quiet) {
    std::fprintf(stderr, "gearpulse-devtools feed: %zu periods (%.1f s) written to %s\n", periods,
                 static_cast<double>(periods) * o.period / o.rate, o.fifo.c_str());
  }
  return 0;
}

}  // namespace

void add_feed(CLI::App& app, int& status) {
  auto opts = std::make_shared<FeedOptions>();
  CLI::App* cmd = app.add_subcommand(
      "feed", "Play a raw PCM file into a FIFO at real-time pace, one period per write (ALSA file plugin)");
  cmd->add_option("--period", opts->period, "Frames per write; must equal the capture's period size")
      ->capture_default_str();
  cmd->add_option("--rate", opts->rate, "Frames per second")->capture_default_str();
  cmd->add_option("--channels", opts->channels, "Interleaved channels in the file")->capture_default_str();
  cmd->add_option("--format", opts->format, "Sample format: s16, s32 or float (little endian)")
      ->capture_default_str();
  cmd->add_flag("--quiet", opts->quiet, "No summary line");
  cmd->add_flag(
      "--wait-start", opts->wait_start,
      "Open the FIFO, say so on stderr, then write nothing until SIGUSR1 (the stream's start, for a capture "
      "opened early)");
  cmd->add_option("FILE", opts->input, "Raw interleaved PCM file")->required();
  cmd->add_option("FIFO", opts->fifo, "FIFO named as the ALSA file plugin's infile")->required();
  cmd->callback([opts, &status] { status = run_feed(*opts); });
}

}  // namespace gearpulse::cli
