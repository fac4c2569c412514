// A state directory on a file system without locks (some network or FUSE mounts): flock() fails there
// with ENOLCK. The daemon must say so and run, not take it for a second gearpulsed and exit. This
// executable's own flock() stands in front of the C library's (the daemon's code is linked in statically)
// and fails that way while a test asks it to.
#include <catch2/catch.hpp>

#include <dlfcn.h>
#include <sys/file.h>

#include <atomic>
#include <cerrno>
#include <string>
#include <system_error>

#include "common/atomic_file.hpp"
#include "tests/test_util.hpp"

namespace {
std::atomic<bool> no_locks{false};

// Fails every flock() with ENOLCK while it lives.
struct NoLocks {
  NoLocks() { no_locks = true; }
  ~NoLocks() { no_locks = false; }
  NoLocks(const NoLocks&) = delete;
  NoLocks& operator=(const NoLocks&) = delete;
};
}  // namespace

extern "C" int flock(int fd, int operation) {
  if (no_locks) {
    errno = ENOLCK;
    return -1;
  }
  using Fn = int (*)(int, int);
  static const auto real = reinterpret_cast<Fn>(::dlsym(RTLD_NEXT, "flock"));
  return real(fd, operation);
}

using gearpulse::DirectoryLock;
using gearpulse::test::TempDir;

TEST_CASE("state: a directory lock where the file system has no locks is an error, not a second daemon") {
  TempDir dir;
  {
    const NoLocks none;
    try {
      const DirectoryLock lock(dir.path());
      FAIL("no error; held() says " << lock.held());
    } catch (const std::system_error& e) {
      CHECK(e.code().value() == ENOLCK);
      CHECK(std::string(e.what()).find("cannot lock " + (dir / ".lock").string()) == 0);
    }
  }
  // With locks, the same directory is locked, and held.
  const DirectoryLock lock(dir.path());
  CHECK(lock.held());
}
