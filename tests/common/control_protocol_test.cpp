#include <catch2/catch.hpp>

#include <string>

#include <nlohmann/json.hpp>

#include "common/control_protocol.hpp"

using namespace gearpulse::control;
using nlohmann::json;

namespace {

// A status with every field set to a value of its own, nullable fields both ways.
StatusReply full_status() {
  StatusReply s;
  s.speed = 12.5;
  s.speed_kmh = 45.0;
  s.speed_sd = 0.75;
  s.source = "engine";
  s.gear = 3;
  s.pulses = 123456789012ULL;
  s.pulse_frequency = 31.25;
  s.gears = {{1, 0.01, 0.0001, 0.25}, {2, 0.02, 0.0002, 0.75}};
  s.model_state = ModelState::kTrained;
  s.training_samples = 4000;
  s.uptime = 61.5;
  s.output = {"pty", "no-reader", "", 7, 8, 2485.0, std::string("/run/gearpulse/pulse")};
  s.gps = {"no-fix", std::nullopt, 3, 4.5, 2, 1, 9, "127.0.0.1:2947", "gone"};
  s.audio = {"recovering", "hw:1", 48000, 5, 6, "ALSA error -2: No such file or directory",
             "open",       9,      1.7e9, 3};
  s.tracker = {88.0, 12.0, true, 4321, 7};
  s.model.state = ModelState::kTrained;
  s.model.gears = 2;
  s.model.fit_samples = 3000;
  s.model.training_samples = 4000;
  s.model.new_samples = 1000;
  s.model.retrain_runs = 4;
  s.model.retrain_busy = true;
  s.model.last_retrain = 1.7e9;
  s.model.last_result = "fitted 2 gears";
  s.model.known_gears = {{1, 0.01, 0.0001, json(420), false}, {2, 0.02, 0.0002, json(nullptr), true}};
  s.model.learning = {true, 600.0, std::nullopt, 41, 40};
  s.model.problems = {"training.bin kept as training.bin.corrupt"};
  s.config = {"/etc/gearpulse/gearpulse.toml", "", {"audio.rate"}};
  s.threads = {{"capture"}, {}, {"pulse"}};
  s.clients = 2;
  return s;
}

}  // namespace

TEST_CASE("control: a status reply is written with the fields and types of docs/interfaces.md") {
  // The status reply as docs/interfaces.md lists it, written out field by field: the structs give it
  // byte for byte.
  const json expected = {
      {"speed", 12.5},
      {"speed_kmh", 45.0},
      {"speed_sd", 0.75},
      {"source", "engine"},
      {"gear", 3},
      {"pulses", 123456789012ULL},
      {"pulse_frequency", 31.25},
      {"gears",
       {{{"gear", 1}, {"theta", 0.01}, {"stderr", 0.0001}, {"weight", 0.25}},
        {{"gear", 2}, {"theta", 0.02}, {"stderr", 0.0002}, {"weight", 0.75}}}},
      {"model_state", "trained"},
      {"training_samples", 4000},
      {"uptime", 61.5},
      {"output",
       {{"kind", "pty"},
        {"state", "no-reader"},
        {"error", ""},
        {"dropped", 7},
        {"unheard", 8},
        {"pulses_per_km", 2485.0},
        {"path", "/run/gearpulse/pulse"}}},
      {"gps",
       {{"state", "no-fix"},
        {"speed", nullptr},
        {"mode", 3},
        {"age", 4.5},
        {"reconnects", 2},
        {"implausible", 1},
        {"unmeasured", 9},
        {"server", "127.0.0.1:2947"},
        {"error", "gone"}}},
      {"audio",
       {{"state", "recovering"},
        {"device", "hw:1"},
        {"rate", 48000},
        {"xruns", 5},
        {"ring_drops", 6},
        {"error", "ALSA error -2: No such file or directory"},
        {"failed_step", "open"},
        {"open_attempts", 9},
        {"last_attempt", 1.7e9},
        {"reopens", 3}}},
      {"tracker", {{"freq", 88.0}, {"snr_db", 12.0}, {"confident", true}, {"turns", 4321}, {"late_hops", 7}}},
      {"model",
       {{"state", "trained"},
        {"gears", 2},
        {"fit_samples", 3000},
        {"training_samples", 4000},
        {"new_samples", 1000},
        {"retrain_runs", 4},
        {"retrain_busy", true},
        {"last_retrain", 1.7e9},
        {"last_result", "fitted 2 gears"},
        {"known_gears",
         {{{"gear", 1}, {"theta", 0.01}, {"stderr", 0.0001}, {"pairs", 420}, {"kept", false}},
          {{"gear", 2}, {"theta", 0.02}, {"stderr", 0.0002}, {"pairs", nullptr}, {"kept", true}}}},
        {"learning",
         {{"young", true},
          {"moving_time", 600.0},
          {"next_refit", nullptr},
          {"cluster_pairs", 41},
          {"first_fit_pairs", 40}}},
        {"problems", {"training.bin kept as training.bin.corrupt"}}}},
      {"config",
       {{"file", "/etc/gearpulse/gearpulse.toml"},
        {"reload_error", ""},
        {"restart_pending", {"audio.rate"}}}},
      {"threads", {{"stalled", {"capture"}}, {"missing", json::array()}, {"realtime_refused", {"pulse"}}}},
      {"clients", 2},
  };
  CHECK(to_json(full_status()).dump() == expected.dump());
  // Fields that are absent unless they apply: the output's path (not for output none), the model's reason.
  StatusReply s = full_status();
  s.output.path.reset();
  s.model.reason = "no gear ladder";
  const json j = to_json(s);
  CHECK_FALSE(j["output"].contains("path"));
  CHECK(j["model"]["reason"] == "no gear ladder");
}

TEST_CASE("control: every reply reads back as it was written") {
  const StatusReply s = full_status();
  CHECK(to_json(status_from_json(to_json(s))).dump() == to_json(s).dump());
  StatusReply bare;
  CHECK(to_json(status_from_json(to_json(bare))).dump() == to_json(bare).dump());

  const GearsReply g{s.gears, ModelState::kTrained, json{{"version", 1}}, 12};
  CHECK(
      to_json(g).dump() ==
      R"({"gears":[{"gear":1,"stderr":0.0001,"theta":0.01,"weight":0.25},{"gear":2,"stderr":0.0002,"theta":0.02,"weight":0.75}],"model":{"version":1},"model_state":"trained","training_samples":12})");
  CHECK(to_json(gears_from_json(to_json(g))).dump() == to_json(g).dump());
  CHECK(to_json(GearsReply{}).dump() ==
        R"({"gears":[],"model":null,"model_state":"learning","training_samples":0})");
  CHECK(to_json(RetrainReply{.training_samples = 5}).dump() == R"({"queued":true,"training_samples":5})");
  CHECK(retrain_from_json(to_json(RetrainReply{.training_samples = 5})).training_samples == 5);
  CHECK(to_json(ResetReply{.training_samples = 0}).dump() == R"({"reset":true,"training_samples":0})");
  CHECK(reset_from_json(json{{"reset", true}, {"training_samples", 9}}).training_samples == 9);
}

TEST_CASE("control: a reply of another shape is refused, an absent field keeps its default") {
  CHECK_THROWS_AS(status_from_json(json::array({1, 2})), ReplyError);
  CHECK_THROWS_AS(status_from_json(json{{"gps", 5}}), ReplyError);
  CHECK_THROWS_AS(status_from_json(json{{"gears", {1}}}), ReplyError);
  CHECK_THROWS_AS(status_from_json(json{{"speed", "fast"}}), ReplyError);
  CHECK_THROWS_AS(status_from_json(json{{"pulses", -1}}), ReplyError);
  CHECK_THROWS_AS(status_from_json(json{{"model_state", "sleeping"}}), ReplyError);
  CHECK_THROWS_AS(gears_from_json(json{{"training_samples", 1.5}}), ReplyError);
  const StatusReply partial = status_from_json(json{{"speed", 1.5}, {"future_field", {1, 2}}});
  CHECK(partial.speed == 1.5);
  CHECK(partial.gps.state.empty());
  CHECK_FALSE(partial.tracker.freq.has_value());
}

TEST_CASE("control: the envelope of requests and replies") {
  CHECK(to_json(Request{.command = Command::kStatus}).dump() == R"({"cmd":"status","v":1})");
  CHECK(to_json(Request{.command = Command::kResetModel, .confirm = true}).dump() ==
        R"({"cmd":"reset-model","confirm":true,"v":1})");
  CHECK(to_json(Request{.command = Command::kResetModel, .confirm = true, .keep_samples = true}).dump() ==
        R"({"cmd":"reset-model","confirm":true,"keep_samples":true,"v":1})");
  for (const Command c : kCommands) {
    CHECK(command_from_string(to_string(c)) == c);
    const Request r = parse_request(to_json(Request{.command = c, .confirm = true}));
    CHECK(r.command == c);
  }
  CHECK_FALSE(command_from_string("Status").has_value());

  CHECK(seal_reply(json{{"x", 1}}).dump() == R"({"ok":true,"v":1,"x":1})");
  CHECK(seal_reply(json::array()).dump() == R"({"ok":true,"v":1})");
  CHECK(seal_reply(json{{"ok", false}, {"error", "busy"}}).dump() == R"({"error":"busy","ok":false,"v":1})");
  CHECK(error_reply("no").dump() == R"({"error":"no","ok":false,"v":1})");
  CHECK(reply_ok(json{{"ok", true}}));
  CHECK_FALSE(reply_ok(json::object()));
  CHECK_THROWS_AS(reply_ok(json{{"ok", "yes"}}), ReplyError);
  CHECK_THROWS_AS(reply_ok(json::array({1, 2})), ReplyError);
  CHECK(reply_error(json{{"ok", false}}) == "request failed");
  CHECK_THROWS_AS(reply_error(json{{"ok", false}, {"error", 5}}), ReplyError);
}

TEST_CASE("control: requests the daemon refuses are refused with the words of the contract") {
  CHECK_THROWS_WITH(parse_request(json{{"cmd", "st\x01tus"}}),
                    "unknown command 'st\\u0001tus' (status, gears, retrain, reset-model)");
  CHECK_THROWS_WITH(parse_request(json{{"cmd", "reset-model"}}),
                    "reset-model forgets the learned gears; send \"confirm\": true to do it");
  CHECK_THROWS_WITH(parse_request(json{{"cmd", "reset-model"}, {"confirm", 1}}),
                    "reset-model forgets the learned gears; send \"confirm\": true to do it");
  CHECK_THROWS_WITH(parse_request(json{{"cmd", "reset-model"}, {"confirm", true}, {"keep_samples", "yes"}}),
                    "reset-model: \"keep_samples\" is true or false");
  CHECK(parse_request(json{{"cmd", "reset-model"}, {"confirm", true}, {"keep_samples", true}}).keep_samples);
  // Fields of another command are ignored.
  CHECK(parse_request(json{{"cmd", "status"}, {"confirm", "x"}}).command == Command::kStatus);
  CHECK_THROWS_AS(check_request_envelope(json{{"v", 2}, {"cmd", "status"}}), ControlError);
  CHECK_THROWS_AS(check_request_envelope(json{{"v", 1}}), ControlError);
  CHECK_NOTHROW(check_request_envelope(json{{"cmd", "anything"}}));
}
