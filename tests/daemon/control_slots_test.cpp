// The control server under load: many clients, its slots, other users, no descriptors, slow readers.
#include <catch2/catch.hpp>

#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/control_server.hpp"
#include "drivers/unique_fd.hpp"
#include "tests/daemon/control_echo.hpp"
#include "tests/test_util.hpp"

using gearpulse::daemon::ControlLimits;
using gearpulse::daemon::ControlServer;
using gearpulse::test::ask;
using gearpulse::test::EchoHandler;
using gearpulse::test::LineClient;
using gearpulse::test::TempDir;
using nlohmann::json;

TEST_CASE("control: many clients at once") {
  TempDir dir;
  ControlServer server((dir / "ctl.sock").string(), EchoHandler{}, ControlLimits{.max_clients = 64});
  server.start();
  constexpr int kClients = 40;
  std::vector<std::unique_ptr<LineClient>> clients;
  for (int i = 0; i < kClients; ++i) {
    clients.push_back(std::make_unique<LineClient>((dir / "ctl.sock").string()));
    REQUIRE(clients.back()->connected());
  }
  // All connected at the same time, each gets its own answers.
  for (int round = 0; round < 3; ++round)
    for (int i = 0; i < kClients; ++i)
      REQUIRE(clients[i]->send_all("{\"cmd\":\"c" + std::to_string(i) + "\"}\n"));
  for (int round = 0; round < 3; ++round)
    for (int i = 0; i < kClients; ++i) {
      const auto line = clients[i]->read_line();
      REQUIRE(line.has_value());
      std::string expected = "c";
      expected += std::to_string(i);
      CHECK(json::parse(*line)["echo"].get<std::string>() == expected);
    }
  // Concurrent threads too.
  std::atomic<int> good{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 8; ++t)
    threads.emplace_back([&] {
      for (int k = 0; k < 20; ++k) {
        LineClient c((dir / "ctl.sock").string());
        if (!c.connected() || !c.send_all("{\"cmd\":\"t\"}\n")) continue;
        if (const auto line = c.read_line(); line && json::parse(*line)["ok"] == true) ++good;
      }
    });
  for (auto& t : threads)
    t.join();
  CHECK(good.load() == 160);
}

TEST_CASE("control: with every slot taken, the connection that asked least recently makes room") {
  TempDir dir;
  ControlServer server((dir / "ctl.sock").string(), EchoHandler{}, ControlLimits{.max_clients = 3});
  server.start();
  LineClient a((dir / "ctl.sock").string()), b((dir / "ctl.sock").string()), c((dir / "ctl.sock").string());
  CHECK(ask(a, R"({"cmd":"x"})")["ok"] == true);
  CHECK(ask(b, R"({"cmd":"x"})")["ok"] == true);
  CHECK(ask(c, R"({"cmd":"x"})")["ok"] == true);
  // a asks again, with a request refused: that is no activity, a still asked least recently.
  CHECK(ask(a, R"({"cmd":"boom"})")["ok"] == false);
  CHECK(ask(b, R"({"cmd":"x"})")["ok"] == true);
  LineClient d((dir / "ctl.sock").string());
  CHECK(ask(d, R"({"cmd":"y"})")["echo"] == "y");
  const auto line = a.read_line();
  REQUIRE(line.has_value());
  CHECK(json::parse(*line)["error"].get<std::string>().find("closed for a new client") != std::string::npos);
  CHECK(a.closed_by_peer());
  CHECK(ask(b, R"({"cmd":"z"})")["echo"] == "z");
  CHECK(ask(c, R"({"cmd":"z"})")["echo"] == "z");
  CHECK(server.clients() == 3);
}

TEST_CASE("control: every slot held by silent and trickling connections still lets a request in") {
  // 32 connections (the default limit) that send a newline every 0.2 s, and 32 that say nothing: a
  // status request on a new connection is answered at once, again and again.
  TempDir dir;
  ControlServer server((dir / "ctl.sock").string(), EchoHandler{});
  server.start();
  std::vector<std::unique_ptr<LineClient>> trickling, silent;
  for (int i = 0; i < 32; ++i) {
    trickling.push_back(std::make_unique<LineClient>((dir / "ctl.sock").string()));
    silent.push_back(std::make_unique<LineClient>((dir / "ctl.sock").string()));
  }
  for (int round = 0; round < 5; ++round) {
    for (auto& c : trickling)
      (void)c->send_all("\n");
    LineClient status((dir / "ctl.sock").string());
    CHECK(ask(status, R"({"cmd":"status"})")["echo"] == "status");
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  CHECK(server.clients() <= 32);
}

TEST_CASE("control: stray bytes keep no slot: a trickling connection goes before one that asked") {
  TempDir dir;
  ControlServer server(
      (dir / "ctl.sock").string(), EchoHandler{},
      ControlLimits{.max_clients = 2, .idle_timeout_ms = 60'000, .first_request_timeout_ms = 1'000});
  server.start();
  LineClient talker((dir / "ctl.sock").string());
  CHECK(ask(talker, R"({"cmd":"x"})")["ok"] == true);
  // Connected after the talker's request, and sending all the time: newlines, a request never finished.
  LineClient trickler((dir / "ctl.sock").string());
  REQUIRE(trickler.send_all("\n{\"cmd\":"));
  LineClient next((dir / "ctl.sock").string());
  CHECK(ask(next, R"({"cmd":"y"})")["echo"] == "y");
  CHECK(trickler.closed_by_peer());
  CHECK(ask(talker, R"({"cmd":"z"})")["echo"] == "z");
  // Alone, a trickle of blank lines and bytes does not renew the first-request timeout either.
  LineClient slow((dir / "ctl.sock").string());
  const auto start = std::chrono::steady_clock::now();
  bool closed = false;
  while (!closed && std::chrono::steady_clock::now() - start < std::chrono::seconds(6)) {
    closed = !slow.send_all("\n ") || slow.closed_by_peer(100);
  }
  CHECK(closed);
}

namespace {

// Connections of another user (nobody, uid 65534) from a child process: `count` of them, each sending a
// newline every 25 ms, and a new one every 50 ms after that, all from the moment the child is up until
// it is killed. Needs root (to change uid); the socket and its directory are opened to every user.
class OtherUsersFlood {
 public:
  OtherUsersFlood(const std::filesystem::path& socket, int count) {
    ::chmod(socket.parent_path().c_str(), 0755);
    ::chmod(socket.c_str(), 0666);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, socket.c_str(), sizeof addr.sun_path - 1);
    int ready[2];
    REQUIRE(::pipe(ready) == 0);
    gearpulse::UniqueFd ready_read(ready[0]), ready_write(ready[1]);
    pid_ = ::fork();
    REQUIRE(pid_ >= 0);
    if (pid_ == 0) {  // async-signal-safe calls only from here
      ::close(ready[0]);
      if (::setgid(65534) != 0 || ::setuid(65534) != 0) ::_exit(1);
      constexpr int kMax = 900;
      int fds[kMax];
      int n = 0;
      const auto connect_one = [&] {
        if (n == kMax) return;
        const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
        if (fd >= 0 && ::connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) == 0)
          fds[n++] = fd;
        else if (fd >= 0)
          ::close(fd);
      };
      for (int i = 0; i < count; ++i)
        connect_one();
      [[maybe_unused]] const ssize_t w = ::write(ready[1], "r", 1);
      for (int tick = 0;; ++tick) {
        for (int i = 0; i < n; ++i)
          (void)::send(fds[i], "\n", 1, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (tick % 2 == 0) connect_one();
        const timespec pause{0, 25'000'000};
        ::nanosleep(&pause, nullptr);
      }
    }
    ready_write.reset();
    char byte = 0;
    REQUIRE(::read(ready_read.get(), &byte, 1) == 1);
  }
  ~OtherUsersFlood() {
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
  }
  OtherUsersFlood(const OtherUsersFlood&) = delete;
  OtherUsersFlood& operator=(const OtherUsersFlood&) = delete;

 private:
  pid_t pid_ = -1;
};

}  // namespace

TEST_CASE("control: other users' connections never take the slot kept for the daemon's uid or root") {
  if (::geteuid() != 0) {
    std::puts("GEARPULSE_SKIP: needs root to connect as another user");
    return;
  }
  TempDir dir;
  const auto sock = dir / "ctl.sock";
  ControlServer server(sock.string(), EchoHandler{}, ControlLimits{.max_clients = 4});
  server.start();
  // 40 connections of another user that send newlines and never a request, and more coming.
  const OtherUsersFlood flood(sock, 40);
  CHECK(gearpulse::test::wait_for([&] { return server.clients() == 3; }, std::chrono::seconds(5)));
  // Root asks, on a connection held through the churn: answered every time, never closed for the others.
  LineClient mine(sock.string());
  for (int i = 0; i < 5; ++i) {
    CHECK(ask(mine, R"({"cmd":"status"})")["echo"] == "status");
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  // A second connection of root's takes a slot of theirs, and both of root's are served.
  LineClient second(sock.string());
  CHECK(ask(second, R"({"cmd":"status"})")["echo"] == "status");
  CHECK(ask(mine, R"({"cmd":"status"})")["echo"] == "status");
  // Every slot taken again: waited for, since the churn goes on (one of theirs that never asked is closed
  // after its first-request timeout, and the slot is empty until their next connection).
  CHECK(gearpulse::test::wait_for([&] { return server.clients() == 4; }, std::chrono::seconds(5)));
}

TEST_CASE("control: connections that never ask anything give their slots back soon") {
  TempDir dir;
  ControlServer server(
      (dir / "ctl.sock").string(), EchoHandler{},
      ControlLimits{.max_clients = 2, .idle_timeout_ms = 60'000, .first_request_timeout_ms = 1'000});
  server.start();
  LineClient talker((dir / "ctl.sock").string()), mute((dir / "ctl.sock").string());
  CHECK(ask(talker, R"({"cmd":"x"})")["ok"] == true);
  // The silent one is closed after the short timeout; the one that spoke keeps its slot (a minute). The
  // second is room for the talker's first request on a loaded machine (from its connect it must beat the
  // timeout) and well inside the wait for the close below.
  CHECK(mute.closed_by_peer(5'000));
  LineClient next((dir / "ctl.sock").string());
  CHECK(ask(next, R"({"cmd":"y"})")["echo"].get<std::string>() == "y");
  CHECK(ask(talker, R"({"cmd":"z"})")["echo"].get<std::string>() == "z");
}

TEST_CASE("control: out of file descriptors the server waits instead of spinning, then serves again") {
#if defined(__SANITIZE_ADDRESS__)
  // The server logs while no descriptor is free, and the sanitizers' runtime checks the logger's types by
  // probing memory through a pipe: without descriptors it reports every such check as a bad object.
  GEARPULSE_SKIP_TEST("AddressSanitizer's runtime needs the file descriptors this test takes away");
#endif
  TempDir dir;
  const std::string path = (dir / "ctl.sock").string();
  ControlServer server(path, EchoHandler{});
  server.start();
  const gearpulse::UniqueFd socket(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0));
  REQUIRE(socket);
  const int s = socket.get();
  // Use up this process's descriptors (the server runs in it), under a lowered limit.
  rlimit old{};
  REQUIRE(::getrlimit(RLIMIT_NOFILE, &old) == 0);
  rlimit low = old;
  low.rlim_cur = std::min<rlim_t>(old.rlim_cur, 512);
  REQUIRE(::setrlimit(RLIMIT_NOFILE, &low) == 0);
  std::vector<gearpulse::UniqueFd> hogs;
  for (int fd; (fd = ::dup(s)) >= 0;)
    hogs.emplace_back(fd);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, path.c_str(), sizeof addr.sun_path - 1);
  REQUIRE(::connect(s, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) == 0);  // queued: not accepted
  // accept() now fails with EMFILE while the listening socket stays readable: a server that kept it in
  // its epoll set would spin a core meanwhile.
  const auto cpu = [] {
    timespec ts{};
    ::clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  };
  const double cpu0 = cpu();
  std::this_thread::sleep_for(std::chrono::seconds(1));
  const double busy = cpu() - cpu0;
  hogs.clear();
  REQUIRE(::setrlimit(RLIMIT_NOFILE, &old) == 0);
  INFO("CPU seconds used over one second without descriptors: " << busy);
  CHECK(busy < 0.3);
  // Descriptors back: the waiting connection is accepted and served.
  const std::string request = "{\"cmd\":\"after\"}\n";
  REQUIRE(::send(s, request.data(), request.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(request.size()));
  timeval tv{5, 0};
  ::setsockopt(s, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  std::string reply;
  char buf[256];
  for (ssize_t n; reply.find('\n') == std::string::npos && (n = ::recv(s, buf, sizeof buf, 0)) > 0;)
    reply.append(buf, static_cast<std::size_t>(n));
  REQUIRE(reply.find('\n') != std::string::npos);
  CHECK(json::parse(reply.substr(0, reply.find('\n')))["echo"] == "after");
}

TEST_CASE("control: a stuck client never blocks the others") {
  TempDir dir;
  ControlServer server((dir / "ctl.sock").string(), EchoHandler{},
                       ControlLimits{.max_output_bytes = 64 * 1024});
  server.start();
  LineClient stuck((dir / "ctl.sock").string());
  REQUIRE(stuck.connected());
  // It asks for large replies and never reads them: the socket buffer fills, then its output buffer.
  std::string burst;
  for (int i = 0; i < 50; ++i)
    burst += "{\"cmd\":\"big\"}\n";
  bool sending = true;
  for (int i = 0; i < 200 && sending; ++i) {
    pollfd pfd{stuck.fd(), POLLOUT, 0};
    if (::poll(&pfd, 1, 50) <= 0) break;
    sending = ::send(stuck.fd(), burst.data(), burst.size(), MSG_NOSIGNAL | MSG_DONTWAIT) > 0;
    LineClient other((dir / "ctl.sock").string());
    REQUIRE(other.connected());
    CHECK(ask(other, R"({"cmd":"status"})")["ok"] == true);
  }
  // The server dropped it rather than buffering without bound (waited for: a sanitized server on a
  // loaded machine may take a while to fill the buffer's limit).
  CHECK(gearpulse::test::wait_for([&] { return server.dropped_clients() >= 1; }, std::chrono::seconds(20)));
  LineClient after((dir / "ctl.sock").string());
  CHECK(ask(after, R"({"cmd":"status"})")["ok"] == true);
}

TEST_CASE("control: a client that reads its replies late gets every one, in order") {
  TempDir dir;
  ControlServer server((dir / "ctl.sock").string(), EchoHandler{},
                       ControlLimits{.max_output_bytes = 4 * 1024 * 1024});
  server.start();
  LineClient late((dir / "ctl.sock").string());
  REQUIRE(late.connected());
  // 150 replies of 8 kB each are far more than a socket's buffer: the rest waits in the server until the
  // client reads, while the server goes on serving others.
  constexpr int kRequests = 150;
  std::string burst;
  for (int i = 0; i < kRequests; ++i)
    burst += "{\"cmd\":\"big\"}\n";
  REQUIRE(late.send_all(burst));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  {
    LineClient other((dir / "ctl.sock").string());
    REQUIRE(other.connected());
    CHECK(ask(other, R"({"cmd":"status"})")["ok"] == true);
  }
  int n_before = 0;
  for (int i = 0; i < kRequests; ++i) {
    const auto line = late.read_line();
    REQUIRE(line.has_value());
    const json r = json::parse(*line);
    CHECK(r["blob"].get<std::string>().size() == 8192);
    const int n = r["n"].get<int>();
    CHECK(n > n_before);
    n_before = n;
  }
  // Then it is an ordinary connection again.
  CHECK(ask(late, R"({"cmd":"again"})")["echo"] == "again");
  CHECK(server.dropped_clients() == 0);
}
