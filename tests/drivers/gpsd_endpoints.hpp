#pragma once
// Where a test's GpsdClient connects: a configuration that retries within milliseconds, and loopback
// sockets for a fake gpsd the test plays itself (one that misbehaves, or comes and goes on cue).
#include <netinet/in.h>
#include <sys/socket.h>

#include <catch2/catch.hpp>

#include <chrono>
#include <string>

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

}  // namespace gearpulse::test
