#include "drivers/pty_output.hpp"

#include "drivers/clock.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/file.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <system_error>

namespace gearpulse {
namespace {

[[noreturn]] void fail(const std::filesystem::path& link, const std::string& what, int err = 0) {
  std::string msg = "pty output " + link.string() + ": " + what;
  if (err) msg += ": " + std::string(std::strerror(err));
  throw std::runtime_error(msg);
}

// A file descriptor for the slave side without a path lookup where the kernel offers it (Linux >= 4.13).
UniqueFd open_peer(int master, const std::string& slave_name) noexcept {
#ifdef TIOCGPTPEER
  const int fd = ::ioctl(master, TIOCGPTPEER, O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd >= 0) return UniqueFd(fd);
#endif
  return UniqueFd(::open(slave_name.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC));
}

}  // namespace

PtyOutput::PtyOutput(std::filesystem::path link, std::chrono::nanoseconds max_age)
    : link_(std::move(link)), max_age_ns_(max_age.count()) {
  if (link_.empty()) fail(link_, "empty path");
  const std::filesystem::path dir = link_.has_parent_path() ? link_.parent_path() : ".";
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec))
    fail(link_, "directory " + dir.string() + " does not exist (create it, e.g. with systemd-tmpfiles)");
  const auto st = std::filesystem::symlink_status(link_, ec);
  if (std::filesystem::exists(st) && !std::filesystem::is_symlink(st))
    fail(link_, "exists and is not a symlink (refusing to replace it)");
  // One owner per link: another process publishing its PTY at this path holds this lock (released by the
  // kernel when it exits, however it exits), and its link is not taken from under its reader.
  const std::string lock_path = link_.string() + ".lock";
  lock_.reset(::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600));
  if (const int err = errno; !lock_) fail(link_, "cannot open " + lock_path, err);
  if (::flock(lock_.get(), LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    if (err == EWOULDBLOCK) fail(link_, "in use by another process (it holds " + lock_path + ")");
    fail(link_, "cannot lock " + lock_path, err);
  }

  master_.reset(::posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC));
  if (const int err = errno; !master_) fail(link_, "posix_openpt", err);
  char name[128];
  if (::grantpt(master_.get()) != 0 || ::unlockpt(master_.get()) != 0 ||
      ::ptsname_r(master_.get(), name, sizeof name) != 0) {
    const int err = errno;
    fail(link_, "cannot set up the pseudo-terminal", err);
  }
  slave_name_ = name;
  // Raw mode on the pair (termios ioctls on a Linux master act on the slave): bytes pass unchanged, no
  // echo, no line buffering, so every pulse byte is readable at once.
  termios tio{};
  if (::tcgetattr(master_.get(), &tio) == 0) {
    ::cfmakeraw(&tio);
    ::tcsetattr(master_.get(), TCSANOW, &tio);
  }
  ::chmod(slave_name_.c_str(), 0660);
  // Open and close the slave once: from then on the master reports POLLHUP whenever no reader has the
  // slave open, which is how rise() knows that a pulse would only be queued for nobody.
  (void)open_peer(master_.get(), slave_name_);

  // Publish atomically: a reader never sees a missing or half-made link.
  const std::filesystem::path tmp = link_.string() + ".tmp" + std::to_string(::getpid());
  ::unlink(tmp.c_str());
  if (::symlink(slave_name_.c_str(), tmp.c_str()) != 0 || ::rename(tmp.c_str(), link_.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    fail(link_, "cannot create the symlink to " + slave_name_, err);
  }
}

// The descriptors close after this, the master first: the lock file stays (removing it would race with
// the next owner).
PtyOutput::~PtyOutput() {
  char target[256];
  const ssize_t n = ::readlink(link_.c_str(), target, sizeof target - 1);
  if (n > 0 && std::string(target, static_cast<std::size_t>(n)) == slave_name_) ::unlink(link_.c_str());
}

bool PtyOutput::has_reader() const noexcept {
  pollfd p{master_.get(), 0, 0};
  return !(::poll(&p, 1, 0) > 0 && (p.revents & POLLHUP));
}

void PtyOutput::rise() noexcept {
  pollfd p{master_.get(), 0, 0};
  if (::poll(&p, 1, 0) > 0 && (p.revents & POLLHUP)) {
    if (!idle_) {
      // The reader just left: bytes it did not read would otherwise greet the next reader as a burst of
      // stale pulses. Drop them once, then count pulses as unheard until somebody opens the slave.
      if (const UniqueFd peer = open_peer(master_.get(), slave_name_)) ::tcflush(peer.get(), TCIFLUSH);
      idle_ = true;
    }
    unheard_.fetch_add(1, std::memory_order_release);
    return;
  }
  idle_ = false;
  drop_stale(monotonic_ns());
  static constexpr char kPulse = 'P';
  const ssize_t n = ::write(master_.get(), &kPulse, 1);
  if (n == 1) {
    written_.fetch_add(1, std::memory_order_relaxed);
  } else if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
    overflowed_.fetch_add(1, std::memory_order_relaxed);
  } else if (n < 0 && errno == EIO) {
    unheard_.fetch_add(1, std::memory_order_release);  // the reader vanished between poll and write
  } else {
    last_error_.store(n < 0 ? errno : EIO, std::memory_order_relaxed);  // n == 0: nothing taken
    errors_.fetch_add(1, std::memory_order_release);  // publishes last_error_ with the count
  }
}

void PtyOutput::drop_stale(std::int64_t now_ns) noexcept {
  // Looks a quarter of the shortest age apart, so the last kLooks span four ages.
  const Look& last = looks_[(looks_next_ + kLooks - 1) % kLooks];
  if (last.t_ns != 0 && now_ns - last.t_ns < max_age_ns_ / 4) return;
  const std::uint64_t written = written_.load(std::memory_order_relaxed);
  looks_[looks_next_] = Look{now_ns, written};
  looks_next_ = (looks_next_ + 1) % kLooks;
  const UniqueFd peer = open_peer(master_.get(), slave_name_);
  if (!peer) return;
  int queued = 0;
  if (::ioctl(peer.get(), FIONREAD, &queued) == 0 && queued > 0) {
    // The oldest byte queued is the (written - queued)-th written: before every look that had more
    // written than that. Stale when the earliest of those is over max_age ago (a byte older than every
    // look is older than the earliest look).
    const std::uint64_t oldest =
        written - std::min<std::uint64_t>(written, static_cast<std::uint64_t>(queued));
    std::int64_t written_by_ns = now_ns;
    for (const Look& l : looks_)
      if (l.t_ns != 0 && l.written > oldest) written_by_ns = std::min(written_by_ns, l.t_ns);
    if (now_ns - written_by_ns > max_age_ns_) {
      // Read out rather than flushed: exactly the bytes taken are counted, and bytes still on their way
      // from the master (not yet in the queue FIONREAD counts, but flushed with it) stay for the reader. A
      // flush lost a few pulses uncounted whenever the kernel had not yet moved them.
      char sink[4096];
      auto left = static_cast<std::size_t>(queued);
      while (left > 0) {
        const ssize_t n = ::read(peer.get(), sink, std::min(left, sizeof sink));
        if (n <= 0) break;
        overflowed_.fetch_add(static_cast<std::uint64_t>(n), std::memory_order_relaxed);
        left -= static_cast<std::size_t>(n);
      }
    }
  }
}

std::string PtyOutput::describe() const {
  return "pty " + link_.string() + " -> " + slave_name_;
}

}  // namespace gearpulse
