// gearpulsectl: asks a running gearpulsed over its control socket.
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/time.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstring>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "common/control_protocol.hpp"
#include "core/json_depth.hpp"
#include "drivers/unique_fd.hpp"
#include "gearpulse_version.hpp"

namespace {

constexpr std::size_t kMaxReply = 1 << 20;  // bytes: a status or gears reply is a few kB
// The whole exchange, from connecting to the reply's end: a daemon whose control thread is stuck leaves
// connections in its backlog (connect then blocks once it is full) or may trickle bytes.
constexpr std::chrono::seconds kReplyTimeout{10};

struct Failure {
  std::string message;
  int status;
};

// One request, one reply line.
nlohmann::json ask_daemon(const std::string& path, const nlohmann::json& request) {
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (path.size() >= sizeof addr.sun_path) throw Failure{"socket path too long: " + path, 2};
  std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
  const gearpulse::UniqueFd socket(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0));
  if (!socket) throw Failure{std::string("socket: ") + std::strerror(errno), 1};
  const int fd = socket.get();
  const auto deadline = std::chrono::steady_clock::now() + kReplyTimeout;
  // A Unix socket's blocking connect and send wait at most the send timeout (EAGAIN after it).
  const timeval limit{.tv_sec = kReplyTimeout.count(), .tv_usec = 0};
  if (::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &limit, sizeof limit) != 0)
    throw Failure{std::string("setsockopt: ") + std::strerror(errno), 1};
  if (::connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0) {
    const int err = errno;
    if (err == EAGAIN || err == EWOULDBLOCK)
      throw Failure{"gearpulsed at " + path + " did not take the connection within 10 s (its control " +
                        "thread may be stuck)",
                    1};
    struct stat st {};
    if (err == ECONNREFUSED && ::stat(path.c_str(), &st) == 0 && !S_ISSOCK(st.st_mode))
      throw Failure{path + " is not a socket (is --socket or control.socket right?)", 3};
    if (err == ENOENT || err == ECONNREFUSED)
      throw Failure{"gearpulsed is not running (no daemon at " + path + ")", 3};
    if (err == EACCES)
      throw Failure{"permission denied on " + path + " (are you in the gearpulse group?)", 3};
    throw Failure{"cannot connect to " + path + ": " + std::strerror(err), 3};
  }
  const std::string line = request.dump() + "\n";
  // A daemon that refuses the connection (too many clients) writes its reason and closes before reading:
  // the send then fails, and the reason waiting in the socket is the error to report.
  int send_error = 0;
  for (std::size_t done = 0; done < line.size();) {
    const ssize_t n = ::send(fd, line.data() + done, line.size() - done, MSG_NOSIGNAL);
    if (n < 0) {
      if (errno == EINTR) continue;
      if (errno == EAGAIN || errno == EWOULDBLOCK) throw Failure{"no reply from gearpulsed within 10 s", 1};
      if (errno != EPIPE && errno != ECONNRESET)
        throw Failure{std::string("cannot send request: ") + std::strerror(errno), 1};
      send_error = errno;
      break;
    }
    done += static_cast<std::size_t>(n);
  }
  std::string reply;
  char buf[4096];
  while (reply.find('\n') == std::string::npos) {
    pollfd pfd{fd, POLLIN, 0};
    const auto left =
        std::chrono::ceil<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()).count();
    const int ready = left > 0 ? ::poll(&pfd, 1, static_cast<int>(left)) : 0;
    if (ready == 0) throw Failure{"no reply from gearpulsed within 10 s", 1};
    if (ready < 0) {
      if (errno == EINTR) continue;
      throw Failure{std::string("poll: ") + std::strerror(errno), 1};
    }
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n == 0 || (n < 0 && send_error != 0 && errno != EINTR)) {
      if (send_error != 0)
        throw Failure{std::string("gearpulsed closed the connection before taking the request (") +
                          std::strerror(send_error) + ")",
                      1};
      throw Failure{"gearpulsed closed the connection without a reply", 1};
    }
    if (n < 0) {
      if (errno == EINTR) continue;
      throw Failure{std::string("cannot read reply: ") + std::strerror(errno), 1};
    }
    reply.append(buf, static_cast<std::size_t>(n));
    if (reply.size() > kMaxReply && reply.find('\n') == std::string::npos)
      throw Failure{"gearpulsed sent a reply longer than 1 MiB without ending it", 1};
  }
  reply.resize(reply.find('\n'));
  // A reply nested deeper than any of the daemon's would be copied and printed recursively
  // (core/json_depth.hpp).
  constexpr std::size_t kMaxNesting = 64;
  if (gearpulse::json_nesting(reply) > kMaxNesting)
    throw Failure{"gearpulsed sent a reply nested deeper than " + std::to_string(kMaxNesting) + " levels", 1};
  try {
    return nlohmann::json::parse(reply);
  } catch (const nlohmann::json::exception&) {
    throw Failure{"gearpulsed sent a reply that is not JSON", 1};
  }
}

namespace control = gearpulse::control;

std::string num(std::optional<double> v, int decimals, const char* unit = "") {
  if (!v) return "-";
  char text[64];
  std::snprintf(text, sizeof text, "%.*f%s", decimals, *v, unit);
  return text;
}

// A number as the JSON reply writes it.
std::string text(const nlohmann::json& v) {
  if (v.is_null()) return "-";
  if (v.is_string()) return v.get<std::string>();
  return v.dump();
}

void print_gears(const std::vector<control::GearRow>& gears) {
  if (gears.empty()) {
    std::cout << "  (no gears learned yet)\n";
    return;
  }
  std::cout << "  gear  theta (m/s)/Hz   stderr       weight  km/h at 100 Hz\n";
  for (const control::GearRow& g : gears) {
    char row[160];
    // Speed at 100 Hz of the tracked component (a ripple's frequency is some multiple of the crank's, which
    // the daemon never needs to know, so no km/h per 1000 rpm).
    std::snprintf(row, sizeof row, "  %4d  %14.5f  %10.6f  %8.3f  %8.1f\n", g.gear, g.theta, g.std_error,
                  g.weight, g.theta * 100.0 * 3.6);
    std::cout << row;
  }
}

void print_status(const control::StatusReply& s) {
  const auto& gps = s.gps;
  const auto& audio = s.audio;
  const auto& model = s.model;
  std::cout << "speed        " << num(s.speed, 2, " m/s") << "  (" << num(s.speed_kmh, 1, " km/h") << ")"
            << (s.speed_sd > 0.0 ? "  +/- " + num(s.speed_sd * 3.6, 1, " km/h") : std::string()) << "\n"
            << "source       " << s.source << "\n"
            << "gear         " << (s.gear > 0 ? std::to_string(s.gear) : "-") << "\n"
            << "pulses       " << s.pulses << "  at " << num(s.pulse_frequency, 1, " Hz") << "  output "
            << s.output.kind << " " << s.output.state << "\n"
            << "gps          " << gps.state << "  speed " << num(gps.speed, 2, " m/s") << "  age "
            << num(gps.age, 1, " s") << "  (" << gps.server << ")\n"
            << "audio        " << audio.state << "  " << audio.device << " @ " << audio.rate << " Hz  xruns "
            << audio.xruns << "  ring drops " << audio.ring_drops
            << (audio.reopens > 0 ? "  reopens " + std::to_string(audio.reopens) : std::string()) << "\n"
            << "tracker      " << num(s.tracker.freq, 2, " Hz") << "  SNR " << num(s.tracker.snr_db, 1, " dB")
            << (s.tracker.confident ? "  confident" : "") << "\n"
            << "model        " << control::to_string(model.state) << "  " << model.gears << " gears, "
            << model.training_samples << " training pairs (" << model.new_samples << " new)\n";
  if (!model.last_result.empty()) std::cout << "last retrain " << model.last_result << "\n";
  if (const auto& learning = model.learning; learning.young) {
    std::cout << "learning     " << num(learning.moving_time, 0, " s") << " of moving; ";
    if (model.gears == 0)
      std::cout << "first fit at " << learning.first_fit_pairs << " steady pairs in one gear (now "
                << learning.cluster_pairs << ")\n";
    else
      std::cout << "next refit at " << num(learning.next_refit, 0, " s") << " of moving\n";
  }
  if (!model.known_gears.empty()) {
    std::cout << "known gears ";
    for (const control::KnownGear& g : model.known_gears)
      std::cout << " " << num(g.theta, 4, "") << " (" << text(g.pairs) << " pairs" << (g.kept ? ", kept" : "")
                << ")";
    std::cout << "\n";
  }
  std::cout << "uptime       " << num(s.uptime, 0, " s") << "\n";
  for (const auto& [name, error] :
       {std::pair{"output", s.output.error}, {"gps", gps.error}, {"audio", audio.error}})
    if (!error.empty()) std::cout << "! " << name << ": " << error << "\n";
  // Where the audio fails while it is down, and how long the daemon has been trying to get it back.
  if (!audio.failed_step.empty() || audio.open_attempts > 0) {
    std::string line = audio.failed_step.empty() ? "" : "failed at " + audio.failed_step;
    if (audio.open_attempts > 0) {
      line += (line.empty() ? "" : "; ") + std::to_string(audio.open_attempts) + " attempt(s) to open it";
      const auto now = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch());
      if (audio.last_attempt)
        line += ", the last " + num(std::max(0.0, now.count() - *audio.last_attempt), 1, " s") + " ago";
    }
    std::cout << "! audio: " << line << "\n";
  }
  const auto names = [](const std::vector<std::string>& list) {
    std::string text;
    for (const std::string& name : list)
      text += (text.empty() ? "" : ", ") + name;
    return text;
  };
  // Threads whose heartbeat is stale: the daemon withholds systemd's watchdog until they turn again.
  if (!s.threads.stalled.empty())
    std::cout << "! threads: not responding: " << names(s.threads.stalled) << "\n";
  if (!s.threads.missing.empty())
    std::cout << "! threads: not built in: " << names(s.threads.missing) << "\n";
  if (!s.threads.realtime_refused.empty())
    std::cout << "! threads: refused the real-time set-up audio.realtime asks for: "
              << names(s.threads.realtime_refused) << "\n";
  // The state directory's problems (a file set aside, a save that fails) and the configuration's (a
  // reload refused, settings waiting for a restart): shown as the others, not only in the JSON.
  for (const std::string& p : model.problems)
    std::cout << "! model: " << p << "\n";
  if (!s.config.reload_error.empty()) std::cout << "! config: " << s.config.reload_error << "\n";
  if (!s.config.restart_pending.empty())
    std::cout << "! config: changed, applied at the next restart: " << names(s.config.restart_pending)
              << "\n";
  std::cout << "gears\n";
  print_gears(s.gears);
}

}  // namespace

int main(int argc, char** argv) {
  // A reply into a pipe whose reader has gone is a write that fails (exit 2, as the manual says), not a
  // death by SIGPIPE (141).
  std::signal(SIGPIPE, SIG_IGN);
  CLI::App app{"gearpulsectl: query and control a running gearpulsed"};
  std::string socket = "/run/gearpulse/control.sock";
  bool json = false;
  bool confirm = false;
  bool keep_samples = false;
  app.add_option("--socket", socket, "control socket of gearpulsed")->capture_default_str();
  app.add_flag("--json", json, "print the daemon's raw JSON reply");
  app.set_version_flag("--version", std::string("gearpulsectl ") + gearpulse::kVersion);
  app.require_subcommand(1);
  using control::Command;
  app.add_subcommand(std::string(to_string(Command::kStatus)),
                     "speed, source, gear, pulses, GPS, audio, tracker and model");
  app.add_subcommand(std::string(to_string(Command::kGears)), "the learned gear scales");
  app.add_subcommand(std::string(to_string(Command::kRetrain)),
                     "fit a new model from the training pairs now");
  auto* reset = app.add_subcommand(std::string(to_string(Command::kResetModel)),
                                   "forget the learned model (needs --confirm)");
  reset->add_flag("--confirm", confirm, "really forget the model");
  reset->add_flag("--keep-samples", keep_samples, "keep the stored training pairs");
  for (auto* sub : app.get_subcommands({})) {
    sub->add_flag("--json", json, "print the daemon's raw JSON reply");
    sub->add_option("--socket", socket, "control socket of gearpulsed");
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::RequiredError& e) {
    // An unknown command reads to CLI11 as none at all: name it (the first word that is neither an
    // option nor the value of --socket).
    std::string known;
    for (const CLI::App* sub : app.get_subcommands({}))
      known += (known.empty() ? "" : ", ") + sub->get_name();
    for (int i = 1; i < argc; ++i) {
      const std::string_view arg = argv[i];
      if (arg == "--socket") {
        ++i;
      } else if (!arg.starts_with("-") &&
                 app.get_subcommands([&](const CLI::App* sub) { return sub->get_name() == arg; }).empty()) {
        std::cerr << "gearpulsectl: unknown command '" << arg << "' (commands: " << known << ")\n";
        return 2;
      }
    }
    std::cerr << "gearpulsectl: " << e.what() << "\n";
    return 2;
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    // One line, as every other error of this tool.
    std::cerr << "gearpulsectl: " << e.what() << "\n";
    return 2;
  }
  // Each subcommand is named after the protocol's command word.
  const auto command = control::command_from_string(app.get_subcommands().front()->get_name());
  if (!command) return 2;
  if (*command == control::Command::kResetModel && !confirm) {
    std::cerr << "gearpulsectl: reset-model forgets every learned gear; add --confirm to do it\n";
    return 2;
  }
  const control::Request request{.command = *command, .confirm = confirm, .keep_samples = keep_samples};
  // The reply is printed whole or not at all: a reply of another shape found halfway through the status
  // must not leave half a status on stdout above the error.
  std::ostringstream printed;
  struct Capture {
    std::streambuf* saved;
    explicit Capture(std::ostream& to) : saved(std::cout.rdbuf(to.rdbuf())) {}
    ~Capture() { std::cout.rdbuf(saved); }
    Capture(const Capture&) = delete;
    Capture& operator=(const Capture&) = delete;
  };
  try {
    const nlohmann::json reply = ask_daemon(socket, control::to_json(request));
    std::optional<Capture> capture(std::in_place, printed);
    const bool ok = control::reply_ok(reply);
    if (json) {
      std::cout << reply.dump(2) << "\n";
    } else if (!ok) {
      std::cerr << "gearpulsectl: " << control::reply_error(reply) << "\n";
    } else {
      switch (*command) {
        case control::Command::kStatus:
          print_status(control::status_from_json(reply));
          break;
        case control::Command::kGears: {
          const control::GearsReply gears = control::gears_from_json(reply);
          std::cout << "model " << control::to_string(gears.model_state) << ", " << gears.training_samples
                    << " training pairs\n";
          print_gears(gears.gears);
          break;
        }
        case control::Command::kRetrain:
          std::cout << "retrain queued on " << control::retrain_from_json(reply).training_samples
                    << " training pairs; see 'gearpulsectl status' for the result\n";
          break;
        case control::Command::kResetModel:
          std::cout << "model reset; " << control::reset_from_json(reply).training_samples
                    << " training pairs kept\n";
          break;
      }
    }
    capture.reset();
    std::cout << printed.str() << std::flush;
    // A reply that did not reach stdout (a full disk, /dev/full) is an error, not a success.
    if (!std::cout) {
      std::cerr << "gearpulsectl: cannot write the reply to stdout\n";
      return 2;
    }
    return ok ? 0 : 1;
  } catch (const Failure& f) {
    std::cerr << "gearpulsectl: " << f.message << "\n";
    return f.status;
  } catch (const control::ReplyError& e) {
    // Valid JSON of another shape: not a gearpulsed of this protocol (or a broken one).
    std::cerr << "gearpulsectl: unexpected reply from " << socket << " (" << e.what() << ")\n";
    return 1;
  } catch (const nlohmann::json::exception& e) {
    // Valid JSON of another shape: not a gearpulsed of this protocol (or a broken one).
    std::cerr << "gearpulsectl: unexpected reply from " << socket << " (" << e.what() << ")\n";
    return 1;
  }
}
