// The control server's protocol: requests and replies, their limits and timeouts, the socket file.
#include <catch2/catch.hpp>

#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>

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

TEST_CASE("control: answers one JSON line per request with the protocol version") {
  TempDir dir;
  ControlServer server((dir / "ctl.sock").string(), EchoHandler{});
  server.start();
  struct stat st {};
  REQUIRE(::stat((dir / "ctl.sock").c_str(), &st) == 0);
  CHECK((st.st_mode & 0777) == 0660);
  LineClient c((dir / "ctl.sock").string());
  REQUIRE(c.connected());
  const json r = ask(c, R"({"v":1,"cmd":"status"})");
  CHECK(r["v"] == 1);
  CHECK(r["ok"] == true);
  CHECK(r["echo"] == "status");
  // Two requests in one write are answered in order.
  REQUIRE(c.send_all("{\"cmd\":\"a\"}\n{\"cmd\":\"b\"}\n"));
  CHECK(json::parse(*c.read_line())["echo"] == "a");
  CHECK(json::parse(*c.read_line())["echo"] == "b");
}

TEST_CASE("control: a second start() while serving leaves the server as it was") {
  TempDir dir;
  ControlServer server((dir / "ctl.sock").string(), EchoHandler{});
  server.start();
  server.start();
  LineClient c((dir / "ctl.sock").string());
  REQUIRE(c.connected());
  CHECK(ask(c, R"({"cmd":"status"})")["echo"] == "status");
  server.stop();
  server.stop();
}

// A daemon on its way out saves for seconds after it stops serving: a client must be refused at once
// then, not left waiting for a reply on a socket nobody serves.
TEST_CASE("control: once stopped, the socket is gone and a client is refused at once") {
  TempDir dir;
  const std::string path = (dir / "ctl.sock").string();
  ControlServer server(path, EchoHandler{});
  server.start();
  server.stop();
  CHECK_FALSE(std::filesystem::exists(path));
  LineClient c(path);
  CHECK_FALSE(c.connected());
}

TEST_CASE("control: bad requests get error replies and the connection stays usable") {
  TempDir dir;
  ControlServer server((dir / "ctl.sock").string(), EchoHandler{});
  server.start();
  LineClient c((dir / "ctl.sock").string());
  REQUIRE(c.connected());
  for (const char* bad : {"not json", "[1,2]", "{\"v\":1}", "{\"cmd\":5}", "{\"v\":99,\"cmd\":\"status\"}",
                          "{\"v\":0,\"cmd\":\"status\"}", "{\"v\":\"1\",\"cmd\":\"status\"}",
                          "{\"cmd\":\"boom\"}", "\xff\xfe{"}) {
    INFO(bad);
    const json r = ask(c, bad);
    CHECK(r["ok"] == false);
    CHECK(r["error"].is_string());
    CHECK(r["v"] == 1);
  }
  CHECK(ask(c, R"({"cmd":"status"})")["ok"] == true);
  // A handler's own failure is told apart from a refusal: the user sees it is the daemon's fault.
  const json r = ask(c, R"({"cmd":"crash"})");
  CHECK(r["ok"] == false);
  CHECK(r["error"] == "internal error: state file vanished");
}

TEST_CASE("control: a handler's reply that is not an object, or that says ok itself, keeps its meaning") {
  // A command answered with something other than an object still gets a well-formed reply, and one that
  // declines without throwing is not turned into a success.
  TempDir dir;
  ControlServer server((dir / "ctl.sock").string(), EchoHandler{});
  server.start();
  LineClient c((dir / "ctl.sock").string());
  const json list = ask(c, R"({"cmd":"list"})");
  CHECK(list == json({{"ok", true}, {"v", 1}}));
  const json declined = ask(c, R"({"cmd":"not-now"})");
  CHECK(declined["ok"] == false);
  CHECK(declined["error"] == "busy retraining");
}

TEST_CASE("control: a socket path too long for the address is refused, one byte shorter is served") {
  // sun_path holds 108 bytes with the terminating NUL: a path of 108 characters would be cut short (or
  // overrun the address), so it is refused naming the path.
  TempDir dir;
  const std::string base = (dir / "").string();
  REQUIRE(base.size() < 100);
  const std::string too_long = base + std::string(108 - base.size(), 's');
  REQUIRE(too_long.size() == 108);
  CHECK_THROWS_WITH(ControlServer(too_long, EchoHandler{}),
                    Catch::Contains("too long") && Catch::Contains(too_long));
  CHECK_FALSE(std::filesystem::exists(too_long));
  const std::string longest = too_long.substr(0, 107);
  ControlServer server(longest, EchoHandler{});
  server.start();
  LineClient c(longest);
  CHECK(ask(c, R"({"cmd":"x"})")["ok"] == true);
}

TEST_CASE("control: blank lines get no reply, so replies stay paired with requests") {
  // A client that sends an empty line (or one with a CR from a terminal) before its request must read
  // the request's reply first, not an error for the blank line.
  TempDir dir;
  EchoHandler handler;
  ControlServer server((dir / "ctl.sock").string(), handler);
  server.start();
  LineClient c((dir / "ctl.sock").string());
  REQUIRE(c.send_all("\n  \t \r\n\r\n{\"cmd\":\"a\"}\r\n"));
  const auto line = c.read_line();
  REQUIRE(line.has_value());
  CHECK(json::parse(*line)["echo"] == "a");
  CHECK(ask(c, R"({"cmd":"b"})")["echo"] == "b");
  CHECK(handler.calls->load() == 2);
  CHECK(server.requests() == 2);
}

TEST_CASE("control: a request of exactly the length limit is answered") {
  // max_request_bytes is the longest request served, not the first one refused.
  TempDir dir;
  ControlServer server((dir / "ctl.sock").string(), EchoHandler{}, ControlLimits{.max_request_bytes = 1024});
  server.start();
  const std::string head = "{\"cmd\":\"";
  const std::string request = head + std::string(1024 - head.size() - 2, 'a') + "\"}";
  REQUIRE(request.size() == 1024);
  LineClient c((dir / "ctl.sock").string());
  const json r = ask(c, request);
  CHECK(r["ok"] == true);
  CHECK(r["echo"].get<std::string>().size() == 1024 - head.size() - 2);
  // The CR of a CRLF line is not counted against the limit either.
  CHECK(ask(c, request + "\r")["ok"] == true);
  CHECK_FALSE(c.closed_by_peer(200));
}

TEST_CASE("control: a client that keeps asking keeps its connection past the idle timeout") {
  // The idle timeout counts from the last request, not from the connection: a monitor polling status
  // every few seconds must not be cut off after idle_timeout_ms.
  TempDir dir;
  ControlServer server((dir / "ctl.sock").string(), EchoHandler{},
                       ControlLimits{.idle_timeout_ms = 2'000, .first_request_timeout_ms = 2'000});
  server.start();
  LineClient c((dir / "ctl.sock").string());
  // 3 s of asking, a request every 0.3 s: past the timeout, with 1.7 s to spare at every gap on a slow
  // machine.
  for (int i = 0; i < 10; ++i) {
    CHECK(ask(c, R"({"cmd":"poll"})")["echo"] == "poll");
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
  }
  CHECK(server.dropped_clients() == 0);
  // Silent for longer than the timeout, it is closed.
  CHECK(c.closed_by_peer(8'000));
  CHECK(server.dropped_clients() == 1);
}

TEST_CASE("control: an oversize request gets an error reply and is disconnected") {
  TempDir dir;
  EchoHandler handler;
  ControlServer server((dir / "ctl.sock").string(), handler, ControlLimits{.max_request_bytes = 1024});
  server.start();
  SECTION("one long line") {
    LineClient c((dir / "ctl.sock").string());
    REQUIRE(c.send_all("{\"cmd\":\"" + std::string(5000, 'a') + "\"}\n"));
    const auto line = c.read_line();
    REQUIRE(line.has_value());
    const json r = json::parse(*line);
    CHECK(r["ok"] == false);
    CHECK(r["error"].get<std::string>().find("longer than 1024") != std::string::npos);
    CHECK(c.closed_by_peer());
  }
  SECTION("endless bytes without a newline") {
    LineClient c((dir / "ctl.sock").string());
    c.send_all(std::string(3000, ' '));
    const auto line = c.read_line();
    REQUIRE(line.has_value());
    CHECK(json::parse(*line)["ok"] == false);
    CHECK(c.closed_by_peer());
  }
  CHECK(handler.calls->load() == 0);
  // The server still serves others.
  LineClient d((dir / "ctl.sock").string());
  CHECK(ask(d, R"({"cmd":"status"})")["ok"] == true);
}

TEST_CASE("control: a client that half-closes still gets its reply") {
  TempDir dir;
  ControlServer server((dir / "ctl.sock").string(), EchoHandler{});
  server.start();
  LineClient c((dir / "ctl.sock").string());
  REQUIRE(c.send_all("{\"cmd\":\"status\"}\n"));
  ::shutdown(c.fd(), SHUT_WR);
  const auto line = c.read_line();
  REQUIRE(line.has_value());
  CHECK(json::parse(*line)["echo"] == "status");
  CHECK(c.closed_by_peer());
}

TEST_CASE("control: a last request ended by a half-close instead of a newline is answered") {
  TempDir dir;
  ControlServer server((dir / "ctl.sock").string(), EchoHandler{});
  server.start();
  LineClient c((dir / "ctl.sock").string());
  REQUIRE(c.send_all("{\"cmd\":\"a\"}\n{\"cmd\":\"b\"}"));
  ::shutdown(c.fd(), SHUT_WR);
  const auto first = c.read_line();
  REQUIRE(first.has_value());
  CHECK(json::parse(*first)["echo"] == "a");
  const auto last = c.read_line();
  REQUIRE(last.has_value());
  CHECK(json::parse(*last)["echo"] == "b");
  CHECK(c.closed_by_peer());
  CHECK(server.requests() == 2);
}

TEST_CASE("control: a stale socket file is replaced and a live one is refused") {
  TempDir dir;
  const std::string path = (dir / "ctl.sock").string();
  {
    // A socket file whose owner died: bound, never unlinked.
    const gearpulse::UniqueFd fd(::socket(AF_UNIX, SOCK_STREAM, 0));
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, path.c_str(), sizeof addr.sun_path - 1);
    REQUIRE(::bind(fd.get(), reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0);
  }
  REQUIRE(std::filesystem::exists(path));
  ControlServer server(path, EchoHandler{});
  server.start();
  LineClient c(path);
  CHECK(ask(c, R"({"cmd":"x"})")["ok"] == true);
  CHECK_THROWS_WITH(ControlServer(path, EchoHandler{}), Catch::Contains("already serving"));
  // A regular file at the path is never deleted.
  gearpulse::test::write_text(dir / "file.sock", "precious");
  CHECK_THROWS_WITH(ControlServer((dir / "file.sock").string(), EchoHandler{}),
                    Catch::Contains("not a socket"));
  CHECK(gearpulse::test::read_text(dir / "file.sock") == "precious");
}

TEST_CASE("control: stopping removes the socket file") {
  TempDir dir;
  {
    ControlServer server((dir / "ctl.sock").string(), EchoHandler{});
    server.start();
    CHECK(std::filesystem::exists(dir / "ctl.sock"));
  }
  CHECK_FALSE(std::filesystem::exists(dir / "ctl.sock"));
}
