#pragma once
// Where a test's GpsdClient connects: a configuration that retries within milliseconds, and loopback
// sockets for a fake gpsd the test plays itself (one that misbehaves, or comes and goes on cue).
#include <netinet/in.h>
#include <sys/socket.h>

#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "drivers/gpsd_client.hpp"
#include "drivers/unique_fd.hpp"

namespace gearpulse::test {

// A client of the gpsd on `port` whose reconnect delay grows from 50 to 400 ms.
inline GpsdConfig config_for(int port) {
  using namespace std::chrono_literals;
  GpsdConfig c;
  c.port = std::to_string(port);
  c.backoff_min = 50ms;
  c.backoff_max = 400ms;
  return c;
}

struct LoopbackSocket {
  UniqueFd fd;
  int port = 0;
};

// A TCP socket bound on 127.0.0.1 at a free port, not yet listening (connections to it are refused).
inline LoopbackSocket loopback_bound() {
  UniqueFd fd(::socket(AF_INET, SOCK_STREAM, 0));
  REQUIRE(fd);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  REQUIRE(::bind(fd.get(), reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
  REQUIRE(::getsockname(fd.get(), reinterpret_cast<sockaddr*>(&a), &len) == 0);
  return {std::move(fd), ntohs(a.sin_port)};
}

// A listening TCP socket on 127.0.0.1 at a free port, for a fake gpsd.
inline LoopbackSocket loopback_listener() {
  LoopbackSocket s = loopback_bound();
  REQUIRE(::listen(s.fd.get(), 4) == 0);
  return s;
}

// A gpsd the test plays on a loopback port: `serve` runs for each connection accepted, on a thread of its
// own, with the connection and a flag set when the fake goes (stop at it). Declared before the client, so
// that the client stops first.
class FakeGpsd {
 public:
  using Serve = std::function<void(int fd, const std::atomic<bool>& done)>;
  explicit FakeGpsd(Serve serve) : socket_(loopback_listener()), serve_(std::move(serve)) {
    thread_ = std::thread([this] {
      while (!done_) {
        const UniqueFd c(::accept(socket_.fd.get(), nullptr, nullptr));
        if (!c) break;
        serve_(c.get(), done_);
      }
    });
  }
  ~FakeGpsd() {
    done_ = true;
    ::shutdown(socket_.fd.get(), SHUT_RDWR);  // wakes the accept
    thread_.join();
  }
  FakeGpsd(const FakeGpsd&) = delete;
  FakeGpsd& operator=(const FakeGpsd&) = delete;
  [[nodiscard]] int port() const noexcept { return socket_.port; }

 private:
  LoopbackSocket socket_;
  Serve serve_;
  std::atomic<bool> done_{false};
  std::thread thread_;
};

// Every report the client publishes, for checks after the run.
struct Recorder {
  std::mutex mutex;
  std::vector<GpsReport> reports;
  GpsdClient::Callback callback() {
    return [this](const GpsReport& r) {
      std::lock_guard lock(mutex);
      reports.push_back(r);
    };
  }
  std::vector<GpsReport> snapshot() {
    std::lock_guard lock(mutex);
    return reports;
  }
  std::size_t usable() {
    std::lock_guard lock(mutex);
    return static_cast<std::size_t>(
        std::count_if(reports.begin(), reports.end(), [](const GpsReport& r) { return r.usable(); }));
  }
  std::size_t size() {
    std::lock_guard lock(mutex);
    return reports.size();
  }
  // True once a report of fix time `first` or earlier came before one of `last` or later: a whole pass of
  // a repeated log arrived, whenever the client joined it.
  bool saw_pass(double first, double last) {
    std::lock_guard lock(mutex);
    const auto start =
        std::find_if(reports.begin(), reports.end(), [&](const GpsReport& r) { return r.fix_time <= first; });
    return std::any_of(start, reports.end(), [&](const GpsReport& r) { return r.fix_time >= last; });
  }
};

}  // namespace gearpulse::test
