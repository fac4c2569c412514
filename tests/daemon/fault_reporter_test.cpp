// The tracker thread's faults: posted as numbers without logging, said by the main thread.
#include <catch2/catch.hpp>

#include <atomic>
#include <chrono>
#include <thread>

#include "daemon/fault_reporter.hpp"
#include "tests/daemon/log_lines.hpp"

using gearpulse::AlsaCaptureStats;
using gearpulse::daemon::FaultNote;
using gearpulse::daemon::FaultReporter;
using Kind = gearpulse::daemon::FaultNote::Kind;

TEST_CASE("faults: what the tracker thread posts is said only by say_notes, in order and in full") {
  gearpulse::test::LogLines log;
  FaultReporter faults("hw:9");
  std::thread tracker([&] {
    faults.post({Kind::kAudioHole, 480});
    faults.post({Kind::kAudioStalled, 3, 0, 2.5});
    faults.post({Kind::kAudioStalledEnd});
    faults.post({Kind::kModelRejected, 12});
  });
  tracker.join();
  CHECK(log.count("hw:9") == 0);
  faults.say_notes();
  CHECK(log.count("audio: 480 frames from hw:9 lost before the ring") == 1);
  CHECK(log.count("audio: no samples from hw:9 for 2.5 s") == 1);
  CHECK(log.count("(stalled 2 time(s) more since the last report)") == 1);
  CHECK(log.count("audio: samples from hw:9 come again") == 1);
  CHECK(log.count("synthesis: cannot use the new model (12 gears is more than it supports)") == 1);
  faults.say_notes();  // said once
  CHECK(log.count("hw:9") == 3);
}

TEST_CASE("faults: a lost capture is posted when it starts and when it ends, said as the journal had it") {
  gearpulse::test::LogLines log;
  FaultReporter faults("hw:9");
  AlsaCaptureStats s;
  s.running = true;
  s.streaming = false;
  s.last_error = -5;
  s.failed_step = gearpulse::AlsaStep::kRead;
  s.reopens = 2;
  const auto t0 = std::chrono::steady_clock::now();
  faults.audio(s, t0);
  faults.audio(s, t0 + std::chrono::milliseconds(10));  // still lost: nothing more
  s.streaming = true;
  faults.audio(s, t0 + std::chrono::milliseconds(20));
  faults.say_notes();
  CHECK(log.count("audio: capture from hw:9 interrupted (ALSA error -5: ") == 1);
  CHECK(log.count("Input/output error, in read); the driver keeps reopening it") == 1);
  CHECK(log.count("audio: capture from hw:9 resumed (2 reopen(s) so far)") == 1);
}

// Posting from one thread while another says: every note is said once; notes beyond the ring's room
// (the main thread held up) are counted and the count is said.
TEST_CASE("faults: notes posted while the main thread says them all arrive, and an overflow is counted") {
  gearpulse::test::LogLines log;
  FaultReporter faults("hw:9");
  constexpr int kNotes = 200;  // fits the ring without a consumer: none may be lost
  std::atomic<bool> done{false};
  std::thread tracker([&] {
    for (int i = 0; i < kNotes; ++i)
      faults.post({Kind::kAudioFrozenEnd});
    done.store(true);
  });
  while (!done.load())
    faults.say_notes();
  tracker.join();
  faults.say_notes();
  CHECK(log.count("audio: samples from hw:9 change again") == kNotes);
  CHECK(log.count("lost (the main thread did not take them in time)") == 0);
  for (int i = 0; i < 300; ++i)
    faults.post({Kind::kAudioFrozenEnd});
  faults.say_notes();
  CHECK(log.count("faults: 44 report(s) of the tracker thread lost") == 1);
}
