#include "daemon/control_server.hpp"

#include <fcntl.h>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <string_view>
#include <system_error>
#include <tuple>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "daemon/log_limiter.hpp"

namespace gearpulse::daemon {
namespace {

[[noreturn]] void throw_errno(const std::string& what) {
  throw std::system_error(errno, std::generic_category(), what);
}

sockaddr_un make_address(const std::string& path) {
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (path.size() >= sizeof addr.sun_path) throw std::runtime_error("control socket path too long: " + path);
  std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
  return addr;
}

// A socket file at `path`: live daemon -> error; dead one (connection refused) -> removed.
void clear_stale_socket(const std::string& path) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0) return;
  if (!S_ISSOCK(st.st_mode))
    throw std::runtime_error("control socket path " + path + " exists and is not a socket; not touching it");
  UniqueFd probe(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0));
  if (!probe) throw_errno("cannot create a socket to probe " + path);
  const sockaddr_un addr = make_address(path);
  const int rc = ::connect(probe.get(), reinterpret_cast<const sockaddr*>(&addr), sizeof addr);
  const int err = errno;
  probe.reset();
  if (rc == 0) throw std::runtime_error("another gearpulsed is already serving " + path);
  if (err != ECONNREFUSED && err != ENOENT)
    throw std::system_error(err, std::generic_category(), "cannot probe existing socket " + path);
  spdlog::info("control: removing stale socket {} left by a previous run", path);
  if (::unlink(path.c_str()) != 0 && errno != ENOENT) throw_errno("cannot remove stale socket " + path);
}

// A peer with the daemon's own uid or root: gearpulsectl run by the service's user or an administrator.
bool peer_is_owner(int fd) noexcept {
  ucred cred{};
  socklen_t len = sizeof cred;
  if (::getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cred, &len) != 0) return false;
  return cred.uid == 0 || cred.uid == ::geteuid();
}

struct Client {
  UniqueFd fd;
  std::string in;
  std::string out;
  bool close_after_flush = false;
  bool owner = false;      // the peer has the daemon's uid or is root
  bool requested = false;  // has completed a request answered ok
  std::uint32_t events = EPOLLIN | EPOLLRDHUP;
  // The last request answered ok, or the connection's start before the first: only requests renew it.
  std::chrono::steady_clock::time_point last_request;
};

// Which client gives its slot to a new connection: one that has completed no request before one that
// has, then the one whose last request (or start) is oldest. A connection of another user may only take
// another such connection's slot. Returns -1 when none may go.
int slot_to_free(const std::map<int, std::unique_ptr<Client>>& clients, bool for_owner) {
  int victim = -1;
  const Client* worst = nullptr;
  for (const auto& [fd, c] : clients) {
    if (c->owner && !for_owner) continue;
    const auto rank = [](const Client& x) { return std::tuple(x.owner, x.requested, x.last_request); };
    if (!worst || rank(*c) < rank(*worst)) {
      worst = c.get();
      victim = fd;
    }
  }
  return victim;
}

// The server's wake-up, or an error naming the socket it was for.
WakeEvent make_wake_event(const std::string& path) {
  try {
    return WakeEvent();
  } catch (const std::system_error& e) {
    throw std::system_error(e.code(), "control socket " + path + ": eventfd");
  }
}

}  // namespace

ControlServer::ControlServer(std::string socket_path, Handler handler, ControlLimits limits)
    : path_(std::move(socket_path)),
      handler_(std::move(handler)),
      limits_(limits),
      wake_(make_wake_event(path_)) {
  const std::filesystem::path parent = std::filesystem::path(path_).parent_path();
  if (!parent.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(parent, ec);
    if (ec)
      throw std::system_error(ec, "cannot create directory " + parent.string() + " for the control socket");
  }
  clear_stale_socket(path_);
  listen_fd_.reset(::socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0));
  if (!listen_fd_) throw_errno("cannot create the control socket " + path_);
  const sockaddr_un addr = make_address(path_);
  // A bind that fails leaves the path as it was: another daemon may have bound it since the stale
  // check, and its socket is not this one's to remove.
  if (::bind(listen_fd_.get(), reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0)
    throw_errno("cannot bind control socket " + path_);
  try {
    // Owner and group (the gearpulse group) may talk to the daemon; nobody else. Set before listen so
    // no connection is ever accepted under a wider mode.
    if (::chmod(path_.c_str(), 0660) != 0) throw_errno("cannot chmod control socket " + path_);
    if (::listen(listen_fd_.get(), 16) != 0) throw_errno("cannot listen on " + path_);
    epoll_fd_.reset(::epoll_create1(EPOLL_CLOEXEC));
    if (!epoll_fd_) throw_errno("control socket " + path_ + ": epoll_create1");
  } catch (...) {
    ::unlink(path_.c_str());  // the descriptors close as the members go
    throw;
  }
}

ControlServer::~ControlServer() {
  stop();
}

void ControlServer::start() {
  if (thread_.joinable()) return;  // serving already
  running_.store(true);
  thread_ = std::thread([this] { run(); });
}

void ControlServer::stop() noexcept {
  if (thread_.joinable()) {
    running_.store(false);
    wake_.signal();  // after the flag: the server thread sees it when epoll_wait returns, or does not wait
    thread_.join();
  }
  // The socket goes with the serving: a daemon on its way out (its last save may take seconds) must not
  // leave a client waiting 10 s for a reply that never comes; it is told at once that nothing listens.
  if (listen_fd_) {
    listen_fd_.reset();
    ::unlink(path_.c_str());
  }
}

std::string ControlServer::handle_line(std::string_view line) const {
  return respond(line).line;
}

ControlServer::Reply ControlServer::respond(std::string_view line) const {
  nlohmann::json reply;
  try {
    nlohmann::json request;
    try {
      request = nlohmann::json::parse(line);
    } catch (const nlohmann::json::exception&) {
      throw ControlError("request is not valid JSON");
    }
    control::check_request_envelope(request);
    reply = control::seal_reply(handler_(request));
  } catch (const ControlError& e) {
    reply = control::error_reply(e.what());
  } catch (const std::exception& e) {
    reply = control::error_reply(std::string("internal error: ") + e.what());
  }
  const bool ok = control::reply_ok(reply);
  // Replacement of invalid UTF-8 keeps a reply valid whatever a handler echoed back.
  return {reply.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace), ok};
}

void ControlServer::run() noexcept {
  std::map<int, std::unique_ptr<Client>> clients;
  std::size_t others = 0;  // clients whose peer is not the daemon's uid nor root
  const std::size_t others_max = limits_.max_clients > 1 ? limits_.max_clients - 1 : limits_.max_clients;
  const auto add_fd = [this](int fd, std::uint32_t events) {
    epoll_event ev{};
    ev.events = events;
    ev.data.fd = fd;
    return ::epoll_ctl(epoll_fd_.get(), EPOLL_CTL_ADD, fd, &ev) == 0;
  };
  const auto set_events = [this](int fd, std::uint32_t events) {
    epoll_event ev{};
    ev.events = events;
    ev.data.fd = fd;
    ::epoll_ctl(epoll_fd_.get(), EPOLL_CTL_MOD, fd, &ev);
  };
  // Counted before the client is told (`goodbye`, a reply line) or closed: whoever reads the goodbye or
  // sees the close and then asks dropped_clients() finds it counted.
  const auto drop = [&](int fd, const char* why, std::string_view goodbye = {}) {
    if (why) {
      dropped_.fetch_add(1, std::memory_order_relaxed);
      spdlog::debug("control: dropping client fd {}: {}", fd, why);
    }
    if (!goodbye.empty()) {
      [[maybe_unused]] const ssize_t w =
          ::send(fd, goodbye.data(), goodbye.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    }
    ::epoll_ctl(epoll_fd_.get(), EPOLL_CTL_DEL, fd, nullptr);
    if (const auto it = clients.find(fd); it != clients.end() && !it->second->owner) --others;
    clients.erase(fd);
    clients_.store(clients.size(), std::memory_order_relaxed);
  };
  // Writes what the socket accepts now; returns false if the client must go.
  const auto flush = [&](Client& c) {
    while (!c.out.empty()) {
      const ssize_t n = ::send(c.fd.get(), c.out.data(), c.out.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
      if (n < 0) {
        if (errno == EINTR) continue;
        if (errno == EAGAIN || errno == EWOULDBLOCK) break;
        return false;
      }
      c.out.erase(0, static_cast<std::size_t>(n));
    }
    if (c.out.empty() && c.close_after_flush) return false;
    // After the last request only the pending replies matter; level-triggered EOF must not spin.
    const std::uint32_t events = (c.close_after_flush ? 0u : std::uint32_t{EPOLLIN | EPOLLRDHUP}) |
                                 (c.out.empty() ? 0u : std::uint32_t{EPOLLOUT});
    if (events != c.events) {
      c.events = events;
      set_events(c.fd.get(), events);
    }
    return true;
  };
  const auto queue = [&](Client& c, std::string line) {
    c.out += line;
    c.out += '\n';
    return c.out.size() <= limits_.max_output_bytes;
  };

  if (!add_fd(listen_fd_.get(), EPOLLIN) || !add_fd(wake_.fd(), EPOLLIN)) {
    spdlog::error("control: epoll registration failed: {}; {} is not served (restart the daemon)",
                  std::strerror(errno), path_);
    return;
  }
  epoll_event events[32];
  // Out of file descriptors (or memory), accept() fails while the listening socket stays readable: it
  // leaves the epoll set for a second instead of waking it at once, forever.
  bool accept_paused = false;
  auto accept_resume = std::chrono::steady_clock::now();
  LogLimiter accept_limiter;
  while (running_.load()) {
    const int n = ::epoll_wait(epoll_fd_.get(), events, 32, accept_paused ? 100 : 1000);
    if (n < 0 && errno != EINTR) {
      spdlog::error("control: epoll_wait failed: {}; {} is no longer served (restart the daemon)",
                    std::strerror(errno), path_);
      break;
    }
    const auto now = std::chrono::steady_clock::now();
    if (accept_paused && now >= accept_resume && add_fd(listen_fd_.get(), EPOLLIN)) accept_paused = false;
    for (int i = 0; i < n; ++i) {
      const int fd = events[i].data.fd;
      if (fd == wake_.fd()) {
        wake_.take_signals();  // the loop's condition then reads running_
        continue;
      }
      if (fd == listen_fd_.get()) {
        for (;;) {
          UniqueFd cfd(::accept4(listen_fd_.get(), nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC));
          if (!cfd) {
            const int err = errno;
            if (err == EAGAIN || err == EWOULDBLOCK || err == EINTR || err == ECONNABORTED) break;
            if (err == EMFILE || err == ENFILE || err == ENOBUFS || err == ENOMEM) {
              ::epoll_ctl(epoll_fd_.get(), EPOLL_CTL_DEL, listen_fd_.get(), nullptr);
              accept_paused = true;
              accept_resume = now + std::chrono::seconds(1);
              std::uint64_t suppressed = 0;
              if (accept_limiter.allow("accept", suppressed))
                spdlog::warn("control: cannot accept a connection: {}; new connections wait a second",
                             std::strerror(err));
            }
            break;
          }
          const bool owner = peer_is_owner(cfd.get());
          if (clients.size() >= limits_.max_clients || (!owner && others >= others_max)) {
            const int victim = slot_to_free(clients, owner);
            if (victim < 0) {
              static constexpr char kBusy[] = "{\"ok\":false,\"error\":\"too many clients\",\"v\":1}\n";
              dropped_.fetch_add(1, std::memory_order_relaxed);  // counted before it is said (drop)
              [[maybe_unused]] const ssize_t w =
                  ::send(cfd.get(), kBusy, sizeof kBusy - 1, MSG_NOSIGNAL | MSG_DONTWAIT);
              continue;
            }
            static constexpr char kEvicted[] =
                "{\"ok\":false,\"error\":\"connection closed for a new client: every slot was taken and "
                "this one had asked least recently\",\"v\":1}\n";
            drop(victim, "its slot given to a new connection", kEvicted);
            std::uint64_t suppressed = 0;
            if (accept_limiter.allow("evict", suppressed))
              spdlog::warn(
                  "control: all {} connections taken; closing the one that asked least recently "
                  "to admit a new one{}",
                  limits_.max_clients,
                  suppressed ? fmt::format(" ({} more since the last report)", suppressed) : "");
          }
          const int key = cfd.get();
          auto c = std::make_unique<Client>();
          c->fd = std::move(cfd);
          c->owner = owner;
          c->last_request = now;
          if (!add_fd(key, EPOLLIN | EPOLLRDHUP)) continue;  // unique_ptr closes it
          others += owner ? 0 : 1;
          clients.emplace(key, std::move(c));
          clients_.store(clients.size(), std::memory_order_relaxed);
        }
        continue;
      }
      const auto it = clients.find(fd);
      if (it == clients.end()) continue;
      Client& c = *it->second;
      if (c.close_after_flush || !(events[i].events & (EPOLLIN | EPOLLRDHUP | EPOLLHUP | EPOLLERR))) {
        if (!flush(c)) drop(fd, nullptr);
        continue;
      }
      bool eof = false, error = false, overflow = false, too_long = false;
      // One request line answered in order (blank ones are not requests); false when the reply does not
      // fit the client's output buffer.
      const auto answer = [&](std::string_view line) {
        if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
        if (line.find_first_not_of(" \t") == std::string_view::npos) return true;
        requests_.fetch_add(1, std::memory_order_relaxed);
        Reply reply = respond(line);
        if (reply.ok) {
          c.requested = true;
          c.last_request = now;
        }
        return queue(c, std::move(reply.line));
      };
      char buf[4096];
      while (!eof && !error && !overflow && !too_long) {
        const ssize_t r = ::recv(fd, buf, sizeof buf, MSG_DONTWAIT);
        if (r == 0) {
          eof = true;
          break;
        }
        if (r < 0) {
          if (errno == EINTR) continue;
          if (errno != EAGAIN && errno != EWOULDBLOCK) error = true;
          break;
        }
        c.in.append(buf, static_cast<std::size_t>(r));
        // Complete lines are answered in order.
        std::size_t start = 0;
        for (std::size_t nl; (nl = c.in.find('\n', start)) != std::string::npos; start = nl + 1) {
          std::string_view line(c.in.data() + start, nl - start);
          if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
          if (line.size() > limits_.max_request_bytes) {
            too_long = true;
            break;
          }
          if (!answer(line)) {
            overflow = true;
            break;
          }
        }
        c.in.erase(0, start);
        if (c.in.size() > limits_.max_request_bytes) too_long = true;
      }
      // A last request ended by the peer's shutdown rather than a newline (printf '{"cmd":"status"}' into
      // a socket) is a line too: answered, not dropped with nothing said.
      if (eof && !error && !overflow && !too_long) {
        overflow = !answer(c.in);
        c.in.clear();
      }
      if (error) {
        drop(fd, "socket error");
        continue;
      }
      if (overflow) {
        drop(fd, "output buffer full (client does not read its replies)");
        continue;
      }
      if (too_long) {
        // Counted here, before the reply that says so: the close comes after the reply is flushed,
        // at once or at a later EPOLLOUT.
        dropped_.fetch_add(1, std::memory_order_relaxed);
        spdlog::debug("control: dropping client fd {}: request too long", fd);
        c.in.clear();
        c.close_after_flush = true;
        queue(c, control::error_reply("request longer than " + std::to_string(limits_.max_request_bytes) +
                                      " bytes; closing the connection")
                     .dump());
      }
      // A peer that shut down its sending side still gets the replies it asked for.
      if (eof) c.close_after_flush = true;
      if (!flush(c)) drop(fd, nullptr);
    }
    // Clients that ask nothing hold a slot; give it back (sooner if they never completed a request).
    for (auto it = clients.begin(); it != clients.end();) {
      const auto idle = std::chrono::duration_cast<std::chrono::milliseconds>(now - it->second->last_request);
      if (idle.count() >
          (it->second->requested ? limits_.idle_timeout_ms : limits_.first_request_timeout_ms)) {
        const int fd = (it++)->first;
        drop(fd, "idle timeout");
      } else {
        ++it;
      }
    }
  }
}

}  // namespace gearpulse::daemon
