#pragma once
// A control handler that echoes each command or fails as told, and one request asked on a LineClient.
#include <catch2/catch.hpp>

#include <atomic>
#include <memory>
#include <stdexcept>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/control_server.hpp"
#include "tests/test_util.hpp"

namespace gearpulse::test {

// A handler that counts calls and echoes the command; "boom" fails like a refused command, "crash" like
// a handler's own fault; "list" answers with an array, "not-now" declines without throwing.
struct EchoHandler {
  std::shared_ptr<std::atomic<int>> calls = std::make_shared<std::atomic<int>>(0);
  nlohmann::json operator()(const nlohmann::json& request) const {
    ++*calls;
    const std::string cmd = request["cmd"].get<std::string>();
    if (cmd == "boom") throw daemon::ControlError("refused on purpose");
    if (cmd == "crash") throw std::runtime_error("state file vanished");
    if (cmd == "list") return nlohmann::json::array({1, 2});
    if (cmd == "not-now") return {{"ok", false}, {"error", "busy retraining"}};
    if (cmd == "big") return {{"blob", std::string(8192, 'x')}, {"n", calls->load()}};
    return {{"echo", cmd}, {"n", calls->load()}};
  }
};

// Sends `line` as one request and returns the reply's JSON.
inline nlohmann::json ask(LineClient& c, const std::string& line) {
  REQUIRE(c.send_all(line + "\n"));
  const auto reply = c.read_line();
  REQUIRE(reply.has_value());
  return nlohmann::json::parse(*reply);
}

}  // namespace gearpulse::test
