// gearpulsectl against the built gearpulsed, and against a socket that is not gearpulsed: its tables and
// JSON, and how it fails.
#include <catch2/catch.hpp>

#include <signal.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/control_server.hpp"
#include "drivers/unique_fd.hpp"
#include "tests/daemon/daemon_process.hpp"
#include "tests/test_util.hpp"

using gearpulse::test::config_for;
using gearpulse::test::kDaemon;
using gearpulse::test::LineClient;
using gearpulse::test::Process;
using gearpulse::test::read_text;
using gearpulse::test::TempDir;
using gearpulse::test::wait_for;
using gearpulse::test::wait_for_status;
using gearpulse::test::write_text;
using nlohmann::json;
using namespace std::chrono_literals;

TEST_CASE("control: gearpulsectl prints status tables and JSON and fails clearly without a daemon") {
  TempDir dir;
  const std::string ctl = GEARPULSE_BINARY_DIR "/tools/gearpulsectl";
  const std::string sock = (dir / "ctl.sock").string();
  {
    Process absent({ctl, "--socket", sock, "status"}, dir / "absent.txt");
    const auto rc = absent.wait();
    REQUIRE(rc.has_value());
    CHECK(*rc != 0);
    CHECK(read_text(dir / "absent.txt").find("gearpulsed is not running") != std::string::npos);
    Process unknown({ctl, "--socket", sock, "--json", "frobnicate"}, dir / "unknown.txt");
    CHECK(unknown.wait() == 2);
    CHECK(read_text(dir / "unknown.txt").find("unknown command 'frobnicate'") != std::string::npos);
  }
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  REQUIRE(wait_for_status(dir, daemon).is_object());

  // The daemon's PCM does not exist: the audio is retried, and status says where it fails.
  REQUIRE(wait_for([&] { return wait_for_status(dir, daemon)["audio"]["open_attempts"] >= 1; }, 20s));
  Process table({ctl, "--socket", sock, "status"}, dir / "table.txt");
  CHECK(table.wait() == 0);
  const std::string text = read_text(dir / "table.txt");
  CHECK(text.find("source") != std::string::npos);
  CHECK(text.find("model        learning") != std::string::npos);
  CHECK(text.find("! audio: ALSA capture 'gearpulse_test_no_such_pcm': cannot open") != std::string::npos);
  CHECK(text.find("! audio: failed at open; ") != std::string::npos);
  CHECK(text.find(" attempt(s) to open it, the last ") != std::string::npos);

  Process full({ctl, "--socket", sock, "status"}, "/dev/full");  // a reply that cannot be written
  CHECK(full.wait() == 2);
  // Nor can one into a pipe whose reader has gone: exit 2 as documented, not a death by SIGPIPE (141).
  CHECK(gearpulse::test::run_into_closed_pipe({ctl, "--socket", sock, "status"}, dir / "pipe.txt") == 2);
  CHECK(read_text(dir / "pipe.txt").find("cannot write the reply to stdout") != std::string::npos);

  Process raw({ctl, "--socket", sock, "status", "--json"}, dir / "raw.txt");
  CHECK(raw.wait() == 0);
  const json parsed = json::parse(read_text(dir / "raw.txt"));
  CHECK(parsed["ok"] == true);
  CHECK(parsed.contains("pulses"));
  CHECK(parsed["audio"]["state"] == "retrying");
  CHECK(parsed["audio"]["failed_step"] == "open");
  CHECK(parsed["audio"]["open_attempts"] >= 1);
  CHECK(parsed["audio"]["last_attempt"].is_number());
  CHECK(parsed["audio"]["reopens"] == 0);

  Process refuse({ctl, "--socket", sock, "reset-model"}, dir / "refuse.txt");
  CHECK(refuse.wait() == 2);
  CHECK(read_text(dir / "refuse.txt").find("--confirm") != std::string::npos);
  Process reset({ctl, "--socket", sock, "reset-model", "--confirm"}, dir / "reset.txt");
  CHECK(reset.wait() == 0);
  Process gears({ctl, "--socket", sock, "gears"}, dir / "gears.txt");
  CHECK(gears.wait() == 0);
  Process retrain({ctl, "--socket", sock, "retrain", "--json"}, dir / "retrain.txt");
  CHECK(retrain.wait() == 0);
  CHECK(json::parse(read_text(dir / "retrain.txt"))["queued"] == true);
  // Requests in a loop: each answered, one log line for them every 10 s.
  for (int i = 0; i < 5; ++i) {
    Process again({ctl, "--socket", sock, "retrain"}, dir / "again.txt");
    CHECK(again.wait() == 0);
  }

  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
  const std::string log = read_text(dir / "log.txt");
  std::size_t lines = 0;
  for (std::size_t at = log.find("control: retrain requested"); at != std::string::npos;
       at = log.find("control: retrain requested", at + 1))
    ++lines;
  CHECK(lines == 1);
}

TEST_CASE("control: gearpulsectl reports a daemon's refusal, not the broken pipe it leaves") {
  TempDir dir;
  const std::string ctl = GEARPULSE_BINARY_DIR "/tools/gearpulsectl";
  // The server refuses another user's connection when the daemon's own user (root here) holds every slot.
  const std::string as_nobody = "/usr/bin/setpriv --reuid=65534 --regid=65534 --clear-groups ";
  if (::geteuid() != 0 || !std::filesystem::exists("/usr/bin/setpriv") ||
      std::system((as_nobody + "test -x " + ctl).c_str()) != 0) {
    std::puts("GEARPULSE_SKIP: needs root and a gearpulsectl that user nobody may run");
    return;
  }
  std::filesystem::permissions(dir.path(), std::filesystem::perms::all);
  const std::string sock = (dir / "ctl.sock").string();
  gearpulse::daemon::ControlServer server(
      sock,
      [](const json&) {
        return json{{"x", 1}};
      },
      gearpulse::daemon::ControlLimits{.max_clients = 1});
  server.start();
  std::filesystem::permissions(sock, std::filesystem::perms::all);
  LineClient holder(sock);  // takes the one slot
  REQUIRE(holder.send_all("{\"cmd\":\"status\"}\n"));
  REQUIRE(holder.read_line().has_value());
  // The server writes its reason and closes without reading: most runs' request then meets a closed
  // socket (EPIPE), and the reason waiting in it is what the user must see.
  for (int i = 0; i < 10; ++i) {
    const auto out = dir / ("busy" + std::to_string(i) + ".txt");
    Process p({"/usr/bin/setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", ctl, "--socket", sock,
               "status"},
              out);
    CHECK(p.wait() == 1);
    CHECK(read_text(out) == "gearpulsectl: too many clients\n");
  }
  // A path that is no socket is named as such, not as a daemon that is not running.
  write_text(dir / "plain", "x");
  Process plain({ctl, "--socket", (dir / "plain").string(), "status"}, dir / "plain.txt");
  CHECK(plain.wait() == 3);
  CHECK(read_text(dir / "plain.txt").find("is not a socket") != std::string::npos);
}

namespace {
// A listening Unix socket at `path` that is not gearpulsed, for gearpulsectl to talk to.
gearpulse::UniqueFd listen_unix(const std::string& path, int backlog = 4) {
  gearpulse::UniqueFd listener(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0));
  REQUIRE(listener);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, path.c_str(), sizeof addr.sun_path - 1);
  REQUIRE(::bind(listener.get(), reinterpret_cast<const sockaddr*>(&addr), sizeof addr) == 0);
  REQUIRE(::listen(listener.get(), backlog) == 0);
  return listener;
}

// A thread that answers the next `replies.size()` connections on `listener`, each with its reply line
// after reading the request, as a daemon would (the client may stop reading first: no SIGPIPE).
std::thread serve_replies(int listener, std::vector<std::string> replies) {
  return std::thread([listener, replies = std::move(replies)] {
    for (const std::string& reply : replies) {
      const gearpulse::UniqueFd c(::accept(listener, nullptr, nullptr));
      if (!c) return;
      char buf[512];
      (void)!::read(c.get(), buf, sizeof buf);
      const std::string line = reply + "\n";
      (void)!::send(c.get(), line.data(), line.size(), MSG_NOSIGNAL);
    }
  });
}
}  // namespace

TEST_CASE("control: gearpulsectl reports a reply of the wrong shape instead of aborting") {
  // Something else on the socket (or a broken daemon) answers valid JSON that is not a status.
  TempDir dir;
  const std::string ctl = GEARPULSE_BINARY_DIR "/tools/gearpulsectl";
  const std::string sock = (dir / "ctl.sock").string();
  const gearpulse::UniqueFd listener = listen_unix(sock);
  // The last two: a status whose "gps" is no object (found after the speed line was printed, which then
  // stood above the error), and a reply that never ends (read without bound before).
  const std::vector<std::string> replies = {R"([1,2])",
                                            R"({"ok":"yes"})",
                                            R"({"ok":false,"error":5})",
                                            R"({"ok":true,"gears":[1]})",
                                            R"({"ok":true,"speed":1.5,"gps":5})",
                                            std::string(2 << 20, ' ')};
  std::thread server = serve_replies(listener.get(), replies);
  for (const std::string& reply : replies) {
    INFO(reply.substr(0, 80));
    Process p({ctl, "--socket", sock, "status"}, dir / "out.txt");
    const auto rc = p.wait();
    REQUIRE(rc.has_value());
    CHECK(*rc == 1);
    const std::string out = read_text(dir / "out.txt");
    CHECK(out.rfind("gearpulsectl: ", 0) == 0);
    CHECK(out.find("speed ") == std::string::npos);  // nothing of a status printed above the error
  }
  server.join();
}

TEST_CASE("control: gearpulsectl gives up after 10 s on a stuck daemon, whatever it is stuck in") {
  // A control thread that no longer accepts leaves connections in the socket's backlog, and connect()
  // blocks once it is full; one that accepted may trickle bytes without ending its reply. Either way the
  // whole exchange has 10 s (both hung without a bound before).
  TempDir dir;
  const std::string ctl = GEARPULSE_BINARY_DIR "/tools/gearpulsectl";
  const std::string sock = (dir / "ctl.sock").string();
  SECTION("the backlog full") {
    const gearpulse::UniqueFd listener = listen_unix(sock, 0);
    LineClient first(sock);  // the backlog's one place, never accepted
    REQUIRE(first.connected());
    const auto start = std::chrono::steady_clock::now();
    Process p({ctl, "--socket", sock, "status"}, dir / "out.txt");
    const auto rc = p.wait(30'000);
    REQUIRE(rc.has_value());
    CHECK(*rc == 1);
    CHECK(read_text(dir / "out.txt").find("did not take the connection within 10 s") != std::string::npos);
    CHECK(std::chrono::steady_clock::now() - start < 15s);
  }
  SECTION("a reply that trickles") {
    const gearpulse::UniqueFd listener = listen_unix(sock);
    std::atomic<bool> done = false;
    std::thread server([&] {
      const gearpulse::UniqueFd c(::accept(listener.get(), nullptr, nullptr));
      for (int i = 0; c && !done && i < 100; ++i) {  // a byte every 0.5 s, never a newline
        (void)!::send(c.get(), " ", 1, MSG_NOSIGNAL);
        std::this_thread::sleep_for(500ms);
      }
    });
    const auto start = std::chrono::steady_clock::now();
    Process p({ctl, "--socket", sock, "status"}, dir / "out.txt");
    const auto rc = p.wait(30'000);
    done = true;
    server.join();
    REQUIRE(rc.has_value());
    CHECK(*rc == 1);
    CHECK(read_text(dir / "out.txt") == "gearpulsectl: no reply from gearpulsed within 10 s\n");
    CHECK(std::chrono::steady_clock::now() - start < 15s);
  }
}

TEST_CASE("control: gearpulsectl refuses a reply nested too deep instead of printing it") {
  // Printed with --json (recursively), a reply nested 100,000 deep would overflow the stack or grow to
  // gigabytes of indentation first.
  TempDir dir;
  const std::string ctl = GEARPULSE_BINARY_DIR "/tools/gearpulsectl";
  const std::string sock = (dir / "ctl.sock").string();
  const gearpulse::UniqueFd listener = listen_unix(sock);
  std::thread server = serve_replies(
      listener.get(), {R"({"ok":true,"x":)" + std::string(100000, '[') + std::string(100000, ']') + "}"});
  Process p({ctl, "--socket", sock, "status", "--json"}, dir / "out.txt");
  const auto rc = p.wait();
  server.join();
  REQUIRE(rc.has_value());
  CHECK(*rc == 1);
  CHECK(read_text(dir / "out.txt") == "gearpulsectl: gearpulsed sent a reply nested deeper than 64 levels\n");
}

TEST_CASE("control: gearpulsectl status says which threads are not responding") {
  // A daemon whose tracker and capture threads stopped turning (threads.stalled): the table says so on a
  // "!" line of its own, as it does the other problems, not only the JSON.
  TempDir dir;
  const std::string ctl = GEARPULSE_BINARY_DIR "/tools/gearpulsectl";
  const std::string sock = (dir / "ctl.sock").string();
  const gearpulse::UniqueFd listener = listen_unix(sock);
  std::thread server = serve_replies(
      listener.get(),
      {R"({"ok":true,"v":1,"threads":{"stalled":["tracker","capture"],"missing":[]},)"
       R"("config":{"file":"x.toml","reload_error":"","restart_pending":["audio.rate","audio.device"]}})"});
  Process p({ctl, "--socket", sock, "status"}, dir / "out.txt");
  const auto rc = p.wait();
  server.join();
  REQUIRE(rc.has_value());
  CHECK(*rc == 0);
  const std::string out = read_text(dir / "out.txt");
  INFO(out);
  CHECK(out.find("! threads: not responding: tracker, capture\n") != std::string::npos);
  CHECK(out.find("! threads: not built in") == std::string::npos);
  CHECK(out.find("! config: changed, applied at the next restart: audio.rate, audio.device\n") !=
        std::string::npos);
}
