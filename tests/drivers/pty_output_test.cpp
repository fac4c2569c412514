#include <catch2/catch.hpp>

#include <fcntl.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "drivers/pty_output.hpp"
#include "drivers/pulse_thread.hpp"
#include "drivers/unique_fd.hpp"
#include "tests/test_util.hpp"

using gearpulse::PtyOutput;
using gearpulse::test::TempDir;

namespace {

// A reader of the pulse device, opened through the symlink as a user would.
class Reader {
 public:
  explicit Reader(const std::filesystem::path& path)
      : fd_(::open(path.c_str(), O_RDONLY | O_NOCTTY | O_NONBLOCK)) {
    REQUIRE(fd_);
  }
  void close() { fd_.reset(); }
  // Reads what arrives within `wait` (one read at most).
  std::string read_once(std::chrono::milliseconds wait) {
    pollfd p{fd_.get(), POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(wait.count())) <= 0) return {};
    char buf[4096];
    const ssize_t n = ::read(fd_.get(), buf, sizeof buf);
    return n > 0 ? std::string(buf, static_cast<std::size_t>(n)) : std::string();
  }
  // Reads whatever is there, waiting up to `quiet` for more after each chunk; returns the bytes.
  std::string drain(std::chrono::milliseconds quiet = std::chrono::milliseconds(50)) {
    std::string out;
    for (;;) {
      pollfd p{fd_.get(), POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(quiet.count())) <= 0) break;
      char buf[4096];
      const ssize_t n = ::read(fd_.get(), buf, sizeof buf);
      if (n <= 0) break;
      out.append(buf, static_cast<std::size_t>(n));
    }
    return out;
  }
  // Reads until `n` bytes have come, then what else arrives within drain()'s quiet time (a surplus shows).
  // A byte written to the master reaches the reader's side in a kernel work item of its own, which a
  // loaded machine can hold longer than that quiet time; the 5 s only bound a failing test.
  std::string read_count(std::size_t n) {
    std::string out;
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while (out.size() < n && std::chrono::steady_clock::now() < end)
      out += read_once(std::chrono::milliseconds(10));
    return out + drain();
  }
  [[nodiscard]] int fd() const noexcept { return fd_.get(); }

 private:
  gearpulse::UniqueFd fd_;
};

}  // namespace

TEST_CASE("pty: one byte per rising edge reaches the reader through the symlink") {
  TempDir dir;
  const auto link = dir / "pulse";
  PtyOutput out(link);
  REQUIRE(std::filesystem::is_symlink(link));
  CHECK(std::filesystem::read_symlink(link) == out.slave_name());
  Reader reader(link);
  for (int i = 0; i < 1000; ++i) {
    out.rise();
    out.fall();
  }
  const std::string got = reader.read_count(1000);
  CHECK(got.size() == 1000);
  CHECK(got.find_first_not_of('P') == std::string::npos);
  CHECK(out.written() == 1000);
  CHECK(out.errors() == 0);
  // Raw mode: a byte that a cooked terminal would translate (CR) or hold back passes unchanged.
  termios tio{};
  REQUIRE(::tcgetattr(reader.fd(), &tio) == 0);
  CHECK((tio.c_lflag & (ICANON | ECHO)) == 0);
}

TEST_CASE("pty: survives the reader closing and reopening and sends no stale pulses") {
  TempDir dir;
  const auto link = dir / "pulse";
  PtyOutput out(link);
  for (int i = 0; i < 5; ++i)
    out.rise();  // nobody listens yet
  CHECK(out.unheard() == 5);
  {
    Reader reader(link);
    for (int i = 0; i < 300; ++i)
      out.rise();
    CHECK(reader.read_count(300).size() == 300);
    for (int i = 0; i < 7; ++i)
      out.rise();  // written, then the reader leaves without reading them
  }
  for (int i = 0; i < 400; ++i)
    out.rise();  // nobody listens: must neither block nor fail
  CHECK(out.errors() == 0);
  Reader again(link);
  CHECK(again.drain(std::chrono::milliseconds(20)).empty());  // nothing from before it opened
  for (int i = 0; i < 250; ++i)
    out.rise();
  CHECK(again.read_count(250).size() == 250);
  CHECK(out.written() == 557);
  CHECK(out.unheard() == 405);
}

TEST_CASE("pty: whether a reader has the device open is known from any thread, before any pulse") {
  TempDir dir;
  const auto link = dir / "pulse";
  PtyOutput out(link);
  const gearpulse::PulseOutput& device = out;  // as the pipeline sees it
  CHECK_FALSE(device.has_reader());            // nobody yet
  {
    Reader reader(link);
    CHECK(device.has_reader());
    Reader second(link);
    reader.close();
    CHECK(device.has_reader());  // one reader is still there
  }
  CHECK_FALSE(device.has_reader());
  out.rise();
  CHECK(device.unheard() == 1);
  const gearpulse::NullPulseOutput none;
  CHECK(none.has_reader());  // a device that cannot tell claims no fault
  CHECK(none.unheard() == 0);
}

TEST_CASE("pty: a reader that does not read never blocks the pulse thread") {
  TempDir dir;
  PtyOutput out(dir / "pulse");
  Reader idle(dir / "pulse");
  for (int i = 0; i < 100000; ++i)
    out.rise();  // a blocking write would hang here once the queue is full
  CHECK(out.written() + out.overflowed() == 100000);
  CHECK(out.overflowed() > 0);
  CHECK(out.errors() == 0);
}

// A reader that has the device open but stops reading (a navigator suspended with the screen off) once
// got, when it resumed, every pulse still queued at once: up to the PTY's queue, kilometres of them.
// Pulses older than max_age are dropped instead; a reader that keeps up loses none.
TEST_CASE("pty: a reader that resumes after a stall gets no pulses older than max_age") {
  using namespace std::chrono_literals;
  using Clock = std::chrono::steady_clock;
  TempDir dir;
  PtyOutput out(dir / "pulse", 200ms);
  Reader reader(dir / "pulse");
  // Pulses at 1 kHz for `length`, the reader draining every 20 ms or not at all; returns the pulses sent,
  // their write times in `written` and, reading, the longest time the loop went without a read.
  const auto pulse_for = [&](std::chrono::milliseconds length, bool read, std::string& got,
                             std::vector<Clock::time_point>& written, Clock::duration& unread) {
    const auto start = Clock::now();
    auto next_read = start;
    auto last_read = start;
    std::size_t sent = 0;
    for (auto t = start; t < start + length; t += 1ms) {
      std::this_thread::sleep_until(t);
      out.rise();
      const auto now = Clock::now();
      written.push_back(now);
      ++sent;
      if (read && now >= next_read) {
        unread = std::max(unread, now - last_read);
        got += reader.read_once(0ms);
        last_read = now;
        next_read += 20ms;
      }
    }
    return sent;
  };
  std::string got;
  std::vector<Clock::time_point> written;
  Clock::duration unread{};
  const std::size_t kept_up = pulse_for(1000ms, true, got, written, unread);
  got += reader.drain();
  // Every pulse is read or counted as dropped. None is dropped while the reader keeps up: a pulse waits
  // from its write to the next read. It keeps up while no read comes more than half of max_age after the
  // one before (the other half for a byte the kernel moves to the reader's side only after a read). A
  // loaded machine can hold the loop, the writer and the reader both, for longer: then the reader did not
  // keep up, and dropping what aged is right.
  const auto unread_ms = std::chrono::duration_cast<std::chrono::milliseconds>(unread).count();
  INFO("longest time without a read while keeping up: " << unread_ms << " ms");
  CHECK(got.size() + out.overflowed() == kept_up);
  if (unread < 100ms) {
    CHECK(got.size() == kept_up);
    CHECK(out.overflowed() == 0);
  } else {
    WARN("the loop was held " << unread_ms << " ms: the reader did not keep up, its count is not checked");
  }

  std::string none;
  written.clear();
  const std::uint64_t dropped_before = out.overflowed();
  const std::size_t stalled = pulse_for(1000ms, false, none, written, unread);
  const std::string resumed = reader.drain();
  // What it gets is about the last 200-300 ms of them (max_age and up to two looks' lag), not the whole
  // second: fewer than were written in the last 500 ms. Judged by the write times, not the count alone:
  // a loop a loaded machine holds late catches up in a burst, which may all be recent.
  const auto recent = static_cast<std::size_t>(
      written.end() - std::lower_bound(written.begin(), written.end(), written.back() - 500ms));
  INFO(stalled << " pulses while the reader stalled, " << recent << " in the last 500 ms, " << resumed.size()
               << " read when it resumed");
  CHECK(resumed.size() < recent);
  CHECK(out.overflowed() - dropped_before + resumed.size() == stalled);
  CHECK(out.errors() == 0);
}

// What a stalled reader would get on resuming is what its queue holds: at no moment more than the pulses
// written in the last max_age and the look interval (max_age / 4) before it, whenever it resumes. Counted
// against the pulses' own write times, so a loop that a loaded machine makes late (and that then catches
// up in a burst) is judged by what it wrote when.
TEST_CASE("pty: a stalled reader's queue never holds much more than max_age of pulses") {
  using namespace std::chrono_literals;
  TempDir dir;
  PtyOutput out(dir / "pulse", 200ms);
  Reader reader(dir / "pulse");
  std::vector<std::chrono::steady_clock::time_point> written;
  written.reserve(1500);
  std::size_t recent = 0;  // first pulse written within the last 300 ms
  int most = 0, excess = 0;
  bool counted = true;
  const auto start = std::chrono::steady_clock::now();
  for (auto t = start; t < start + 1500ms; t += 1ms) {  // 1 kHz, never read
    std::this_thread::sleep_until(t);
    out.rise();
    const auto now = std::chrono::steady_clock::now();
    written.push_back(now);
    // 200 ms of age, a look's 50 ms and 50 ms for the loop's own delays.
    while (written[recent] < now - 300ms)
      ++recent;
    int queued = 0;
    counted = counted && ::ioctl(reader.fd(), FIONREAD, &queued) == 0;
    most = std::max(most, queued);
    excess = std::max(excess, queued - static_cast<int>(written.size() - recent));
  }
  INFO("most pulses queued: " << most << ", most beyond those written in the last 300 ms: " << excess);
  REQUIRE(counted);
  CHECK(most >= 150);  // the queue did fill to about max_age
  CHECK(excess <= 0);
  CHECK(out.errors() == 0);
}

TEST_CASE("pty: a missing directory or a non-symlink path is a clear error") {
  TempDir dir;
  try {
    PtyOutput out(dir / "no-such-dir" / "pulse");
    FAIL("no error for a missing directory");
  } catch (const std::runtime_error& e) {
    CHECK(std::string(e.what()).find("does not exist") != std::string::npos);
    CHECK(std::string(e.what()).find("no-such-dir") != std::string::npos);
  }
  std::ofstream(dir / "file") << "x";
  CHECK_THROWS_WITH(PtyOutput(dir / "file"), Catch::Contains("not a symlink"));
}

// A second daemon configured with the same path (another state_dir, another socket) once took the link
// over, and removed it when it stopped: the first one's reader lost its pulses while its status said ok.
TEST_CASE("pty: a link another live owner publishes is not taken over") {
  TempDir dir;
  const auto link = dir / "pulse";
  auto first = std::make_unique<PtyOutput>(link);
  const auto target = std::filesystem::read_symlink(link);
  try {
    PtyOutput second(link);
    FAIL("a second owner took the link");
  } catch (const std::runtime_error& e) {
    CHECK(std::string(e.what()).find("in use by another process") != std::string::npos);
  }
  CHECK(std::filesystem::read_symlink(link) == target);
  first.reset();  // the owner gone (as when it exits, however it exits), the path is free again
  PtyOutput third(link);
  CHECK(std::filesystem::read_symlink(link) == third.slave_name());
}

// The daemon runs as its own user; a navigator reading the pulses is in the device's group and needs to
// open it for reading (a pseudo-terminal is made writable by its group only).
TEST_CASE("pty: the pulse device is readable and writable by its group") {
  TempDir dir;
  PtyOutput out(dir / "pulse");
  struct stat st {};
  REQUIRE(::stat(out.slave_name().c_str(), &st) == 0);
  CHECK((st.st_mode & 0777) == 0660);
}

// A link a user has pointed elsewhere since (another device, another program's PTY) is theirs: closing
// the output removes only a link that still points at its own PTY.
TEST_CASE("pty: a link pointed elsewhere is left in place on close") {
  TempDir dir;
  const auto link = dir / "pulse";
  {
    PtyOutput out(link);
    std::filesystem::remove(link);
    std::filesystem::create_symlink("/dev/null", link);
  }
  REQUIRE(std::filesystem::is_symlink(link));
  CHECK(std::filesystem::read_symlink(link) == "/dev/null");
}

TEST_CASE("pty: a stale symlink is replaced and the link is removed on close") {
  TempDir dir;
  const auto link = dir / "pulse";
  std::filesystem::create_symlink("/dev/pts/does-not-exist", link);
  {
    PtyOutput out(link);
    CHECK(std::filesystem::read_symlink(link) == out.slave_name());
  }
  CHECK_FALSE(std::filesystem::exists(std::filesystem::symlink_status(link)));
}

TEST_CASE("pty: the pulse thread writes one byte per pulse and stops low") {
  TempDir dir;
  PtyOutput out(dir / "pulse");
  Reader reader(dir / "pulse");
  gearpulse::PulseThreadConfig cfg;
  cfg.pulse.pulses_per_km = 10000.0;  // 10 pulses per metre
  std::vector<gearpulse::RiseRecord> log(4096);
  gearpulse::PulseThread thread(out, cfg, log);
  thread.start();
  std::string got;
  auto read_for = [&](std::chrono::milliseconds d) {
    const auto end = std::chrono::steady_clock::now() + d;
    while (std::chrono::steady_clock::now() < end)
      got += reader.read_once(std::chrono::milliseconds(10));
  };
  // Reads until `done` holds and returns whether it did. The 5 s only bound a failing test: what takes
  // a hundred milliseconds here may take a sanitized build on a loaded machine far longer.
  auto read_until = [&](auto done) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while (!done() && std::chrono::steady_clock::now() < end)
      got += reader.read_once(std::chrono::milliseconds(10));
    return done();
  };
  thread.set_speed(20.0);  // 200 Hz
  REQUIRE(read_until([&] { return thread.pulses() >= 20; }));
  thread.set_speed(5.0);  // 50 Hz
  const auto pulses_fast = thread.pulses();
  REQUIRE(read_until([&] { return thread.pulses() >= pulses_fast + 5; }));
  thread.set_speed(std::nan(""));  // standstill
  // The turn after the set_speed loads the standstill. Distance owed under the old speed is still paid:
  // a thread woken more than a period late owes a rise that waits for the fall and the low time before
  // it, so it may come turns later. An owed rise comes within two turns of the edge before it (its
  // fall's turn, then its own); four turns without a rise and nothing is owed. Counted in turns, not in
  // time: a sanitized build on a loaded machine may sleep through any fixed wait.
  const auto turns_set = thread.status().turns;
  REQUIRE(read_until([&] { return thread.status().turns >= turns_set + 2; }));
  auto quiet_from_turn = thread.status().turns;
  auto quiet_pulses = thread.pulses();
  REQUIRE(read_until([&] {
    const auto s = thread.status();
    if (s.pulses != quiet_pulses) {
      quiet_pulses = s.pulses;
      quiet_from_turn = s.turns;
    }
    return s.turns >= quiet_from_turn + 4;
  }));
  const auto pulses_stopped = thread.pulses();
  // An absence has no condition to wait for: a loaded machine only makes this window see less.
  read_for(std::chrono::milliseconds(100));
  CHECK(thread.pulses() == pulses_stopped);  // no pulse at standstill
  thread.stop();
  got += reader.read_count(thread.pulses() > got.size() ? thread.pulses() - got.size() : 0);
  CHECK(thread.pulses() > 20);
  CHECK(got.size() == thread.pulses());
  CHECK(out.written() == thread.pulses());
  CHECK(thread.logged() == thread.pulses());
  bool increasing = true;
  for (std::size_t i = 1; i < thread.logged(); ++i)
    increasing = increasing && log[i].scheduled_ns > log[i - 1].scheduled_ns &&
                 log[i].written_ns >= log[i].scheduled_ns;
  CHECK(increasing);
  CHECK_FALSE(thread.status().running);
}
