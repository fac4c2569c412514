#pragma once
// The control socket: a Unix stream socket (mode 0660) speaking JSON lines (common/control_protocol.hpp),
// served by one thread with epoll and non-blocking sockets. Many clients may be connected at once; a
// client that sends too long a request gets an error reply and is disconnected; a client that does not
// read its replies is dropped once its output buffer is full, so no client can ever block the daemon.
// Slots go to clients that ask: only a complete request answered ok counts as activity (stray bytes,
// blank lines and refused requests do not), and when every slot is taken a new connection takes the slot
// of one that has never completed a request, else of the one idle longest. One slot is kept for a peer
// with the daemon's own uid or root (SO_PEERCRED): other users' connections never hold every slot.
#include <atomic>
#include <cstddef>
#include <functional>
#include <string>
#include <string_view>
#include <thread>

#include <nlohmann/json.hpp>

#include "common/control_protocol.hpp"
#include "drivers/unique_fd.hpp"
#include "drivers/wake_event.hpp"

namespace gearpulse::daemon {

// Thrown by a handler to answer {"ok":false,"error":what()}.
using control::ControlError;

struct ControlLimits {
  std::size_t max_request_bytes = control::kMaxRequestBytes;
  std::size_t max_output_bytes = 256 * 1024;  // per client: beyond it the client is dropped
  // Connections at once; with more than one, the last is kept for the daemon's uid or root.
  unsigned max_clients = 32;
  int idle_timeout_ms = 60'000;  // a connection that asks nothing this long is closed
  // ... and one that has completed no request yet, this long.
  int first_request_timeout_ms = 10'000;
};

using control::quote_text;

class ControlServer {
 public:
  // Called on the server thread with a validated request (an object with a string "cmd"); returns the
  // reply fields. Must not block for long.
  using Handler = std::function<nlohmann::json(const nlohmann::json& request)>;

  // Binds and listens (a stale socket file left by a dead daemon is replaced; a live one is an error).
  // Throws std::system_error / std::runtime_error naming the path.
  ControlServer(std::string socket_path, Handler handler, ControlLimits limits = {});
  ~ControlServer();
  ControlServer(const ControlServer&) = delete;
  ControlServer& operator=(const ControlServer&) = delete;

  void start();  // serves on a thread of its own; once serving, a second start() does nothing
  // Ends the serving and removes the socket (a client then fails to connect at once); a stopped server
  // does not start again.
  void stop() noexcept;

  [[nodiscard]] std::size_t clients() const noexcept { return clients_.load(std::memory_order_relaxed); }
  [[nodiscard]] std::uint64_t requests() const noexcept { return requests_.load(std::memory_order_relaxed); }
  [[nodiscard]] std::uint64_t dropped_clients() const noexcept {
    return dropped_.load(std::memory_order_relaxed);
  }
  [[nodiscard]] const std::string& path() const noexcept { return path_; }

  // Builds the reply line for one request line (without the newline); exposed for tests.
  [[nodiscard]] std::string handle_line(std::string_view line) const;

 private:
  struct Reply {
    std::string line;  // without the newline
    bool ok = false;   // a request answered ok: activity that keeps the connection's slot
  };
  [[nodiscard]] Reply respond(std::string_view line) const;
  void run() noexcept;

  std::string path_;
  Handler handler_;
  ControlLimits limits_;
  UniqueFd listen_fd_;
  UniqueFd epoll_fd_;
  WakeEvent wake_;  // stop() signals it; the server thread waits on it in its epoll set
  std::thread thread_;
  std::atomic<bool> running_{false};
  std::atomic<std::size_t> clients_{0};
  std::atomic<std::uint64_t> requests_{0};
  std::atomic<std::uint64_t> dropped_{0};
};

}  // namespace gearpulse::daemon
