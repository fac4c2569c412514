#pragma once
// No sound card here: the ALSA `file` plugin over a `null` slave returns the bytes of `infile` as the
// captured frames (the null slave accepts whatever rate, format and channels are asked for). A regular
// file is read as fast as the capture asks (unpaced); a FIFO fed one period per period time paces it.
#include <fcntl.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <catch2/catch.hpp>

#include "drivers/clock.hpp"
#include "drivers/unique_fd.hpp"
#include "tests/test_util.hpp"

namespace gearpulse::test {

// `file` is where the plugin writes what it captures (a write that fails there fails the read).
inline void use_alsa_config(const TempDir& dir, const std::string& pcm_name,
                            const std::filesystem::path& infile,
                            const std::filesystem::path& file = "/dev/null") {
  const auto conf = dir / "asound.conf";
  std::ofstream f(conf, std::ios::app);
  f << "pcm." << pcm_name << " { type file slave.pcm null file \"" << file.string() << "\" infile \""
    << infile.string() << "\" format raw }\n";
  f.close();
  ::setenv("ALSA_CONFIG_PATH", ("/usr/share/alsa/alsa.conf:" + conf.string()).c_str(), 1);
}

template <typename T>
inline void write_raw(const std::filesystem::path& path, const std::vector<T>& samples) {
  std::ofstream f(path, std::ios::binary);
  f.write(reinterpret_cast<const char*>(samples.data()),
          static_cast<std::streamsize>(samples.size() * sizeof(T)));
}

// A PCM (named "paced" unless told) whose file plugin reads a fresh FIFO in `dir`; returns the FIFO.
inline std::filesystem::path make_paced_pcm(const TempDir& dir, const std::string& pcm_name = "paced") {
  const auto fifo = dir / (pcm_name + ".fifo");
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  use_alsa_config(dir, pcm_name, fifo);
  return fifo;
}

// What a FIFO writer does once, after `at_period` periods: nothing, stall (stop writing for a while,
// then go on at the period rate from where it stopped), or go away (close its end for a while, then
// open the FIFO again and go on).
struct WriterBreak {
  enum Kind { kNone, kStall, kClose } kind = kNone;
  std::size_t at_period = 0;
  std::chrono::milliseconds length{0};
};

// Feeds a FIFO exactly one period per write at the period rate (other write sizes leave holes). After
// the samples it keeps feeding silence until destroyed, so the capture (whose file plugin blocks in
// read() on the FIFO) can always be stopped first.
class FifoFeeder {
 public:
  FifoFeeder(std::filesystem::path fifo, std::vector<std::int16_t> samples, unsigned period, unsigned rate,
             WriterBreak pause = {})
      : thread_([=, this] {
          ::signal(SIGPIPE, SIG_IGN);  // the capture closing its end must not kill the test
          gearpulse::UniqueFd fd(::open(fifo.c_str(), O_WRONLY));  // blocks until ALSA opens the infile
          if (!fd) return;
          // The pipe would buffer the first ~0.7 s unpaced if writing began before the capture reads.
          while (!go_ && !stop_)
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
          const std::int64_t period_ns = static_cast<std::int64_t>(period) * 1'000'000'000 / rate;
          const std::vector<std::int16_t> silence(period, 0);
          std::int64_t next = gearpulse::monotonic_ns();
          for (std::size_t off = 0, n = 0; !stop_; off += period, ++n) {
            if (pause.kind != WriterBreak::kNone && n == pause.at_period) {
              if (pause.kind == WriterBreak::kClose) fd.reset();
              const auto resume = std::chrono::steady_clock::now() + pause.length;
              while (!stop_ && std::chrono::steady_clock::now() < resume)
                std::this_thread::sleep_for(std::chrono::milliseconds(10));
              if (pause.kind == WriterBreak::kClose) {
                // Without blocking: a reader that has gone meanwhile (the test is over) would hold a
                // blocking open for ever.
                int reopened;
                while ((reopened = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK)) < 0 && errno == ENXIO &&
                       !stop_)
                  std::this_thread::sleep_for(std::chrono::milliseconds(10));
                if (reopened < 0) return;
                fd.reset(reopened);
                ::fcntl(fd.get(), F_SETFL, ::fcntl(fd.get(), F_GETFL) & ~O_NONBLOCK);
              }
              next = gearpulse::monotonic_ns();  // go on at the rate, no catching up
            }
            const timespec ts = gearpulse::to_timespec(next);
            ::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
            const bool data = off + period <= samples.size();
            if (!data) done_ = true;
            if (::write(fd.get(), data ? samples.data() + off : silence.data(),
                        period * sizeof(std::int16_t)) < 0)
              break;
            next += period_ns;
          }
        }) {}
  ~FifoFeeder() {
    stop_ = true;
    thread_.join();
  }
  [[nodiscard]] bool done() const { return done_; }
  void go() { go_ = true; }

 private:
  std::atomic<bool> go_{false};
  std::atomic<bool> stop_{false};
  std::atomic<bool> done_{false};
  std::thread thread_;
};

}  // namespace gearpulse::test
