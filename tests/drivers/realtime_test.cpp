// Real-time set-up: locking memory keeps resident what the process uses, not everything it has mapped.
#include <catch2/catch.hpp>

#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <fstream>
#include <string>
#include <thread>

#include "drivers/realtime.hpp"
#include "tests/test_util.hpp"

#ifndef GEARPULSE_SANITIZED
namespace {

// This process's resident memory, kB (VmRSS).
std::int64_t resident_kb() {
  std::ifstream in("/proc/self/status");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("VmRSS:", 0) == 0) return std::stoll(line.substr(6));
  return -1;
}

constexpr int kNotLocked = 77;

// In a child process (locking is process-wide and lasts): a thread whose 8 MB stack is barely used and
// 64 MB of heap mapped but never touched, then make_realtime with lock_memory. Exits with the growth of
// the resident memory in MB (capped at 76), or kNotLocked when mlockall is not allowed here.
int locked_growth_mb() {
  constexpr std::size_t kUntouched = 64u << 20;
  void* heap = ::mmap(nullptr, kUntouched, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (heap == MAP_FAILED) return 100;
  bool go = false;
  std::thread idle([&go] {
    while (!__atomic_load_n(&go, __ATOMIC_ACQUIRE))
      ::usleep(1000);
  });
  ::usleep(20'000);
  const std::int64_t before = resident_kb();
  const gearpulse::RealtimeResult r = gearpulse::make_realtime({false, 0, true});
  const std::int64_t after = resident_kb();
  __atomic_store_n(&go, true, __ATOMIC_RELEASE);
  idle.join();
  if (!r.memory_locked) return kNotLocked;
  const std::int64_t mb = (after - before) / 1024;
  return static_cast<int>(mb < 0 ? 0 : (mb > 76 ? 76 : mb));
}

}  // namespace
#endif

TEST_CASE("realtime: locked memory is made resident as it is used, not every mapping at once") {
#ifdef GEARPULSE_SANITIZED
  GEARPULSE_SKIP_TEST("a sanitizer's shadow mappings make mlockall meaningless in this build");
#else
  const pid_t pid = ::fork();
  REQUIRE(pid >= 0);
  if (pid == 0) ::_exit(locked_growth_mb());
  int status = 0;
  REQUIRE(::waitpid(pid, &status, 0) == pid);
  REQUIRE(WIFEXITED(status));
  const int growth = WEXITSTATUS(status);
  if (growth == kNotLocked)
    GEARPULSE_SKIP_TEST("mlockall is not allowed here (needs CAP_IPC_LOCK or RLIMIT_MEMLOCK)");
  INFO("resident memory grew by " << growth << " MB when memory was locked");
  // The idle thread's stack (8 MB) and the untouched heap (64 MB) stay out; the caller's stack is touched
  // (a quarter of a MB) so that its real-time loop meets no page fault.
  CHECK(growth < 4);
#endif
}
