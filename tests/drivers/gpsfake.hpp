#pragma once
// A real gpsd started by gpsfake on a port of the test's own, fed from an NMEA log.
#include <netinet/in.h>
#include <signal.h>
#include <sys/ipc.h>
#include <sys/shm.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <thread>

#include "drivers/unique_fd.hpp"
#include "tests/test_util.hpp"

namespace gearpulse::test {

// gpsfake (and the gpsd it runs) in a session of its own, killed as a group.
//
// gpsfake hands its log to gpsd through a control socket named after its own PID in $TMPDIR, and takes
// any file already at that path for gpsd's: a socket left behind by a killed gpsd whose PID is reused
// makes gpsfake add no device, and gpsd then serves no fixes at all. Each instance therefore gets a
// directory of its own. A killed gpsd also leaves the shared-memory segment it keys on the port; it is
// removed with the instance.
class GpsFake {
 public:
  GpsFake(const std::filesystem::path& log, int port, double cycle_s, bool once)
      : port_(port),
        process_(
            args(log, port, cycle_s, once), tmp_.path() / "gpsfake.log",
            // gpsfake is a Python program for Debian's /usr/bin/python3; another may come first.
            {.env = {"PATH=/usr/bin:/usr/sbin:/bin", "TMPDIR=" + tmp_.path().string()}, .own_group = true}) {}
  ~GpsFake() { kill(); }
  GpsFake(const GpsFake&) = delete;
  GpsFake& operator=(const GpsFake&) = delete;

  // True once gpsd accepts connections on `port` (gpsfake takes about a second to start it).
  static bool wait_listening(int port, std::chrono::milliseconds timeout) {
    return wait_for(
        [port] {
          const UniqueFd fd(::socket(AF_INET, SOCK_STREAM, 0));
          sockaddr_in a{};
          a.sin_family = AF_INET;
          a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
          a.sin_port = htons(static_cast<std::uint16_t>(port));
          return fd && ::connect(fd.get(), reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
        },
        timeout);
  }

  // For a test that waited in vain: whether gpsd listens on the port, and what gpsfake and gpsd wrote.
  [[nodiscard]] std::string describe() const {
    return "gpsd on port " + std::to_string(port_) +
           (wait_listening(port_, std::chrono::milliseconds(0)) ? " listens" : " does not listen") +
           "; gpsfake wrote: '" + read_text(tmp_.path() / "gpsfake.log") + "'";
  }

  // SIGSTOP/SIGCONT to gpsfake alone: gpsd stays up and connected but gets nothing from its device, as
  // with a receiver that goes quiet, until it is resumed.
  void pause() { process_.signal(SIGSTOP); }
  void resume() { process_.signal(SIGCONT); }

  // SIGKILL to the whole group: gpsd dies without saying goodbye, as in a crash.
  void kill() {
    process_.kill();
    // gpsfake's key for the port (GPSD_SHM_KEY = 0x4770 followed by the port in four hex digits).
    const int id = ::shmget(static_cast<key_t>(0x47700000 + port_), 0, 0);
    if (id >= 0) ::shmctl(id, IPC_RMID, nullptr);
  }

 private:
  static std::vector<std::string> args(const std::filesystem::path& log, int port, double cycle_s,
                                       bool once) {
    std::vector<std::string> a = {"/usr/bin/gpsfake",   "-q", "-P",
                                  std::to_string(port), "-c", std::to_string(cycle_s)};
    if (once) a.emplace_back("-1");
    a.push_back(log.string());
    return a;
  }

  TempDir tmp_;
  int port_;
  Process process_;
};

}  // namespace gearpulse::test
