#pragma once
// A real gpsd started by gpsfake on a port of the test's own, fed from an NMEA log.
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <thread>

#include "tests/test_util.hpp"

namespace gearpulse::test {

// gpsfake (and the gpsd it runs) in a session of its own, killed as a group.
class GpsFake {
 public:
  GpsFake(const std::filesystem::path& log, int port, double cycle_s, bool once)
      : process_(args(log, port, cycle_s, once), "/dev/null",
                 // gpsfake is a Python program for Debian's /usr/bin/python3; another may come first.
                 {.env = {"PATH=/usr/bin:/usr/sbin:/bin"}, .own_group = true}) {}

  // True once gpsd accepts connections on `port` (gpsfake takes about a second to start it).
  static bool wait_listening(int port, std::chrono::milliseconds timeout) {
    return wait_for(
        [port] {
          const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
          sockaddr_in a{};
          a.sin_family = AF_INET;
          a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
          a.sin_port = htons(static_cast<std::uint16_t>(port));
          const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
          ::close(fd);
          return ok;
        },
        timeout);
  }

  // SIGKILL to the whole group: gpsd dies without saying goodbye, as in a crash.
  void kill() { process_.kill(); }

 private:
  static std::vector<std::string> args(const std::filesystem::path& log, int port, double cycle_s,
                                       bool once) {
    std::vector<std::string> a = {"/usr/bin/gpsfake",   "-q", "-P",
                                  std::to_string(port), "-c", std::to_string(cycle_s)};
    if (once) a.emplace_back("-1");
    a.push_back(log.string());
    return a;
  }

  Process process_;
};

}  // namespace gearpulse::test
