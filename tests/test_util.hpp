#pragma once
// Helpers shared by the tests: skipping a test that cannot run, a sanitizer build, the real driving logs,
// unique temp dirs, shell commands, small text files, free TCP ports, polling for a condition, child
// processes, a line-oriented Unix socket client, and random corruption of a file's text. Everything that
// names a path or a port is unique per call, so test executables can run in parallel.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "drivers/unique_fd.hpp"

// Ends the running test case as skipped: it prints GEARPULSE_SKIP and the reason, which ctest reports as
// "Skipped" (SKIP_REGULAR_EXPRESSION in tests/CMakeLists.txt), and returns from the TEST_CASE. For a test
// that needs hardware, a privilege, data or a program it cannot have; scripts/test.sh fails when a test
// skips that must run there (docs/testing.md).
#define GEARPULSE_SKIP_TEST(reason)     \
  do {                                  \
    WARN("GEARPULSE_SKIP: " << reason); \
    return;                             \
  } while (false)

// Defined in a sanitizer build (GEARPULSE_SANITIZE: AddressSanitizer or ThreadSanitizer): GCC says so with
// __SANITIZE_ADDRESS__ / __SANITIZE_THREAD__, clang through __has_feature.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define GEARPULSE_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define GEARPULSE_SANITIZED 1
#endif
#endif

namespace gearpulse::test {

// How many times longer the threads' own work may take in this build than in the release build, for a
// test that bounds such work in time (a sleep or a timeout is not stretched): ThreadSanitizer's documented
// slowdown is 5-15 times, its upper end taken (AddressSanitizer's, about 2, lies within it); 1 unsanitized.
#ifdef GEARPULSE_SANITIZED
inline constexpr double kSanitizerSlowdown = 15.0;
#else
inline constexpr double kSanitizerSlowdown = 1.0;
#endif

// The third-party driving logs (shared/data/real beside the source tree): $GEARPULSE_REAL_DATA_DIR if set,
// else the directory the build was configured with (the CMake variable of the same name).
inline std::filesystem::path real_data_dir() {
  const char* dir = std::getenv("GEARPULSE_REAL_DATA_DIR");
  return (dir != nullptr && *dir != '\0') ? std::filesystem::path(dir)
                                          : std::filesystem::path(GEARPULSE_REAL_DATA_DIR);
}

// A fresh directory under $TMPDIR, removed with everything in it at scope exit.
class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "gearpulse-test-XXXXXX").string();
    if (!::mkdtemp(tmpl.data())) throw std::runtime_error("mkdtemp failed");
    path_ = tmpl;
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  [[nodiscard]] const std::filesystem::path& path() const noexcept { return path_; }
  [[nodiscard]] std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

// A shell command's exit status (-1 if it did not exit normally) and its standard output.
struct ShellResult {
  int status = -1;
  std::string out;
};

// Runs `command` with /bin/sh; stdout is captured, stderr goes wherever the command sends it.
inline ShellResult run_shell(const std::string& command) {
  ShellResult r;
  std::FILE* p = ::popen(command.c_str(), "r");
  if (p == nullptr) return r;
  char buf[4096];
  std::size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0)
    r.out.append(buf, n);
  const int rc = ::pclose(p);
  r.status = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  return r;
}

// Runs `argv` (argv[0] an absolute path) with stdout a pipe nobody reads any more and stderr to `err`,
// SIGPIPE at its default (as a shell that is not ignoring it leaves it, whatever this process does with
// it): the exit status, or 128 + the signal that ended it, as a shell reports it.
inline int run_into_closed_pipe(const std::vector<std::string>& argv, const std::filesystem::path& err) {
  std::vector<char*> args;
  for (const std::string& a : argv)
    args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  int fds[2];
  if (::pipe(fds) != 0) return -1;
  ::close(fds[0]);
  const gearpulse::UniqueFd out(fds[1]);
  const gearpulse::UniqueFd err_fd(::open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600));
  if (!err_fd) return -1;
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::signal(SIGPIPE, SIG_DFL);
    ::dup2(out.get(), STDOUT_FILENO);
    ::dup2(err_fd.get(), STDERR_FILENO);
    ::execv(args[0], args.data());
    ::_exit(127);
  }
  if (pid < 0) return -1;
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

inline void write_text(const std::filesystem::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary);
  out << text;
}

inline std::string read_text(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// A TCP port on 127.0.0.1 that was free a moment ago, for a server the test starts later. It is drawn
// below the kernel's ephemeral range (/proc/sys/net/ipv4/ip_local_port_range, 32768-60999 by default):
// a port the kernel hands out for bind(0) it also hands out as the source port of any connect on the
// machine, so one of the parallel tests' many connections could hold it by the time the server binds it
// (a gpsd started ten seconds later). Drawn at random, tests running side by side rarely draw the same;
// each draw is checked free by binding it.
inline int free_port() {
  int low = 32768;
  if (std::ifstream range("/proc/sys/net/ipv4/ip_local_port_range"); !(range >> low)) low = 32768;
  const int first = 10000, last = std::max(first + 1000, low) - 1;
  std::mt19937 rng(std::random_device{}() ^ static_cast<unsigned>(::getpid()));
  std::uniform_int_distribution<int> pick(first, last);
  for (int attempt = 0; attempt < 200; ++attempt) {
    const gearpulse::UniqueFd fd(::socket(AF_INET, SOCK_STREAM, 0));
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    const int port = pick(rng);
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    if (fd && ::bind(fd.get(), reinterpret_cast<sockaddr*>(&a), sizeof a) == 0) return port;
  }
  throw std::runtime_error("cannot find a free port below the ephemeral range");
}

// Polls `done` every 20 ms until it holds or `timeout` passes; returns its last value. The timeout only
// bounds a failing test: no assertion depends on how soon `done` holds.
inline bool wait_for(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    if (std::chrono::steady_clock::now() > end) return done();
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}

// A child process running `argv` (argv[0] an absolute path) with stdout and stderr appended to `log`.
// Killed with SIGKILL at scope exit if still running.
struct ProcessOptions {
  std::vector<std::string> env;  // "NAME=value" entries that set or replace the child's variables
  bool own_group = false;        // a session of its own, so kill() takes its children down too
};

class Process {
 public:
  Process(const std::vector<std::string>& argv, const std::filesystem::path& log, ProcessOptions options = {})
      : own_group_(options.own_group) {
    // Everything the child needs is built before fork(): after it only async-signal-safe calls.
    std::vector<std::string> args = argv;
    std::vector<std::string> env = std::move(options.env);
    for (char** e = environ; *e; ++e) {
      const std::string_view entry(*e);
      const std::string_view name = entry.substr(0, entry.find('=') + 1);
      bool replaced = false;
      for (const auto& mine : env)
        replaced = replaced || std::string_view(mine).substr(0, name.size()) == name;
      if (!replaced) env.emplace_back(entry);
    }
    std::vector<char*> argp, envp;
    for (auto& a : args)
      argp.push_back(a.data());
    argp.push_back(nullptr);
    for (auto& e : env)
      envp.push_back(e.data());
    envp.push_back(nullptr);
    const std::string log_path = log.string();
    pid_ = ::fork();
    if (pid_ < 0) throw std::runtime_error("fork failed");
    if (pid_ == 0) {
      if (own_group_) ::setsid();
      const int fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
      if (fd >= 0) {
        ::dup2(fd, 1);
        ::dup2(fd, 2);
      }
      ::execve(argp[0], argp.data(), envp.data());
      ::_exit(127);
    }
  }
  ~Process() { kill(); }
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;

  void signal(int sig) const { ::kill(pid_, sig); }
  [[nodiscard]] pid_t pid() const noexcept { return pid_; }
  // SIGKILL (to the whole group with own_group), as in a crash, and reaps it.
  void kill() {
    if (pid_ <= 0 || exited_) return;
    ::kill(own_group_ ? -pid_ : pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
    exited_ = true;
  }
  // Exit status (or 128 + signal); nullopt if still running after the timeout.
  std::optional<int> wait(int timeout_ms = 20'000) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    for (;;) {
      int status = 0;
      const pid_t r = ::waitpid(pid_, &status, WNOHANG);
      if (r == pid_) {
        exited_ = true;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      if (std::chrono::steady_clock::now() > deadline) return std::nullopt;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }
  [[nodiscard]] bool running() {
    if (exited_) return false;
    int status = 0;
    if (::waitpid(pid_, &status, WNOHANG) == pid_) {
      exited_ = true;
      return false;
    }
    return true;
  }

 private:
  pid_t pid_ = -1;
  bool own_group_ = false;
  bool exited_ = false;
};

// A blocking Unix stream client with a receive deadline.
class LineClient {
 public:
  explicit LineClient(const std::string& path) {
    fd_.reset(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0));
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, path.c_str(), sizeof addr.sun_path - 1);
    if (::connect(fd_.get(), reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0) fd_.reset();
  }
  [[nodiscard]] bool connected() const { return static_cast<bool>(fd_); }
  [[nodiscard]] int fd() const { return fd_.get(); }

  bool send_all(const std::string& data) {
    std::size_t done = 0;
    while (done < data.size()) {
      const ssize_t n = ::send(fd_.get(), data.data() + done, data.size() - done, MSG_NOSIGNAL);
      if (n <= 0) return false;
      done += static_cast<std::size_t>(n);
    }
    return true;
  }
  // Next line, or nullopt on EOF/error/timeout.
  std::optional<std::string> read_line(int timeout_ms = 10'000) {
    for (;;) {
      if (const auto nl = buffer_.find('\n'); nl != std::string::npos) {
        std::string line = buffer_.substr(0, nl);
        buffer_.erase(0, nl + 1);
        return line;
      }
      pollfd pfd{fd_.get(), POLLIN, 0};
      if (::poll(&pfd, 1, timeout_ms) <= 0) return std::nullopt;
      char buf[65536];
      const ssize_t n = ::recv(fd_.get(), buf, sizeof buf, 0);
      if (n <= 0) return std::nullopt;
      buffer_.append(buf, static_cast<std::size_t>(n));
    }
  }
  // True once the peer has closed (reads drain pending data).
  bool closed_by_peer(int timeout_ms = 10'000) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (std::chrono::steady_clock::now() < deadline) {
      pollfd pfd{fd_.get(), POLLIN, 0};
      if (::poll(&pfd, 1, 100) <= 0) continue;
      char buf[65536];
      const ssize_t n = ::recv(fd_.get(), buf, sizeof buf, 0);
      if (n == 0 || (n < 0 && errno != EAGAIN && errno != EINTR)) return true;
    }
    return false;
  }

 private:
  gearpulse::UniqueFd fd_;
  std::string buffer_;
};

// `text` after `edits` random edits of the kind a damaged file shows: a byte replaced, a few dropped,
// one of `pieces` inserted, a stretch repeated (a line written twice), or the rest cut off (a writer
// that died).
inline std::string mangle(std::string text, int edits, const std::vector<std::string>& pieces,
                          std::mt19937& rng) {
  for (int e = 0; e < edits && !text.empty(); ++e) {
    const std::size_t at = rng() % text.size();
    switch (rng() % 5) {
      case 0:
        text[at] = static_cast<char>(rng() % 256);
        break;
      case 1:
        text.erase(at, 1 + rng() % 8);
        break;
      case 2:
        if (!pieces.empty()) text.insert(at, pieces[rng() % pieces.size()]);
        break;
      case 3:
        text.insert(at, text.substr(at, std::min<std::size_t>(1 + rng() % 80, text.size() - at)));
        break;
      default:
        text.resize(at);
    }
  }
  return text;
}

}  // namespace gearpulse::test
