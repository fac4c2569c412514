#include "common/control_protocol.hpp"

#include <concepts>
#include <cstdio>
#include <type_traits>

namespace gearpulse::control {
namespace {

using nlohmann::json;

// The field names of the protocol, each written once: fields(r, f) calls f(name, member) for every
// member of a reply struct, in both directions (Writer builds the JSON, Reader fills the struct).
// On the wire an std::optional<double> is a number or null; an std::optional<std::string> is present or
// absent.
#define GEARPULSE_FIELDS(Type) \
  template <class R, class F>  \
  requires std::same_as<std::remove_const_t<R>, Type>

GEARPULSE_FIELDS(GearRow) void fields(R& r, F&& f) {
  f("gear", r.gear);
  f("theta", r.theta);
  f("stderr", r.std_error);
  f("weight", r.weight);
}

GEARPULSE_FIELDS(KnownGear) void fields(R& r, F&& f) {
  f("gear", r.gear);
  f("theta", r.theta);
  f("stderr", r.std_error);
  f("pairs", r.pairs);
  f("kept", r.kept);
}

GEARPULSE_FIELDS(GearsReply) void fields(R& r, F&& f) {
  f("gears", r.gears);
  f("model_state", r.model_state);
  f("model", r.model);
  f("training_samples", r.training_samples);
}

GEARPULSE_FIELDS(RetrainReply) void fields(R& r, F&& f) {
  f("queued", r.queued);
  f("training_samples", r.training_samples);
}

GEARPULSE_FIELDS(ResetReply) void fields(R& r, F&& f) {
  f("reset", r.reset);
  f("training_samples", r.training_samples);
}

GEARPULSE_FIELDS(OutputStatus) void fields(R& r, F&& f) {
  f("kind", r.kind);
  f("state", r.state);
  f("error", r.error);
  f("dropped", r.dropped);
  f("unheard", r.unheard);
  f("pulses_per_km", r.pulses_per_km);
  f("path", r.path);
}

GEARPULSE_FIELDS(GpsStatus) void fields(R& r, F&& f) {
  f("state", r.state);
  f("speed", r.speed);
  f("mode", r.mode);
  f("age", r.age);
  f("reconnects", r.reconnects);
  f("implausible", r.implausible);
  f("unmeasured", r.unmeasured);
  f("server", r.server);
  f("error", r.error);
}

GEARPULSE_FIELDS(AudioStatus) void fields(R& r, F&& f) {
  f("state", r.state);
  f("device", r.device);
  f("rate", r.rate);
  f("xruns", r.xruns);
  f("ring_drops", r.ring_drops);
  f("error", r.error);
  f("failed_step", r.failed_step);
  f("open_attempts", r.open_attempts);
  f("last_attempt", r.last_attempt);
  f("reopens", r.reopens);
}

GEARPULSE_FIELDS(TrackerStatus) void fields(R& r, F&& f) {
  f("freq", r.freq);
  f("snr_db", r.snr_db);
  f("confident", r.confident);
  f("turns", r.turns);
  f("late_hops", r.late_hops);
}

GEARPULSE_FIELDS(LearningStatus) void fields(R& r, F&& f) {
  f("young", r.young);
  f("moving_time", r.moving_time);
  f("next_refit", r.next_refit);
  f("cluster_pairs", r.cluster_pairs);
  f("first_fit_pairs", r.first_fit_pairs);
}

GEARPULSE_FIELDS(ModelStatus) void fields(R& r, F&& f) {
  f("state", r.state);
  f("gears", r.gears);
  f("fit_samples", r.fit_samples);
  f("training_samples", r.training_samples);
  f("new_samples", r.new_samples);
  f("retrain_runs", r.retrain_runs);
  f("retrain_busy", r.retrain_busy);
  f("last_retrain", r.last_retrain);
  f("last_result", r.last_result);
  f("reason", r.reason);
  f("known_gears", r.known_gears);
  f("learning", r.learning);
  f("problems", r.problems);
}

GEARPULSE_FIELDS(ConfigStatus) void fields(R& r, F&& f) {
  f("file", r.file);
  f("reload_error", r.reload_error);
  f("restart_pending", r.restart_pending);
}

GEARPULSE_FIELDS(ThreadStatus) void fields(R& r, F&& f) {
  f("stalled", r.stalled);
  f("missing", r.missing);
  f("realtime_refused", r.realtime_refused);
}

GEARPULSE_FIELDS(StatusReply) void fields(R& r, F&& f) {
  f("speed", r.speed);
  f("speed_kmh", r.speed_kmh);
  f("speed_sd", r.speed_sd);
  f("source", r.source);
  f("gear", r.gear);
  f("pulses", r.pulses);
  f("pulse_frequency", r.pulse_frequency);
  f("gears", r.gears);
  f("model_state", r.model_state);
  f("training_samples", r.training_samples);
  f("uptime", r.uptime);
  f("output", r.output);
  f("gps", r.gps);
  f("audio", r.audio);
  f("tracker", r.tracker);
  f("model", r.model);
  f("config", r.config);
  f("threads", r.threads);
  f("clients", r.clients);
}

#undef GEARPULSE_FIELDS

template <class T>
concept Record = requires(T& r) {
  fields(r, [](const char*, auto&) {});
};

// ---- Writing.

template <Record T>
json to_object(const T& record);

template <class T>
void put(json& out, const char* key, const T& value) {
  if constexpr (std::same_as<T, std::optional<double>>) {
    out[key] = value ? json(*value) : json(nullptr);
  } else if constexpr (std::same_as<T, std::optional<std::string>>) {
    if (value) out[key] = *value;
  } else if constexpr (std::same_as<T, ModelState>) {
    out[key] = std::string(to_string(value));
  } else if constexpr (Record<T>) {
    out[key] = to_object(value);
  } else if constexpr (std::same_as<T, std::vector<GearRow>> || std::same_as<T, std::vector<KnownGear>>) {
    json rows = json::array();
    for (const auto& row : value)
      rows.push_back(to_object(row));
    out[key] = std::move(rows);
  } else {
    out[key] = value;
  }
}

template <Record T>
json to_object(const T& record) {
  json out = json::object();
  fields(record, [&out](const char* key, const auto& value) { put(out, key, value); });
  return out;
}

// ---- Reading.

[[noreturn]] void wrong_type(const char* what) {
  throw ReplyError(std::string(what) + " has the wrong type");
}

template <Record T>
T from_object(const json& in, const char* what);

template <class T>
void take(const json& in, const char* key, T& value) {
  if constexpr (std::same_as<T, bool>) {
    if (!in.is_boolean()) wrong_type(key);
    value = in.get<bool>();
  } else if constexpr (std::is_integral_v<T> && std::is_unsigned_v<T>) {
    if (!in.is_number_integer() || (!in.is_number_unsigned() && in.get<long long>() < 0)) wrong_type(key);
    value = in.get<T>();
  } else if constexpr (std::is_integral_v<T>) {
    if (!in.is_number_integer()) wrong_type(key);
    value = in.get<T>();
  } else if constexpr (std::same_as<T, double>) {
    if (!in.is_number()) wrong_type(key);
    value = in.get<double>();
  } else if constexpr (std::same_as<T, std::string>) {
    if (!in.is_string()) wrong_type(key);
    value = in.get<std::string>();
  } else if constexpr (std::same_as<T, std::optional<double>>) {
    if (in.is_null()) {
      value.reset();
    } else {
      if (!in.is_number()) wrong_type(key);
      value = in.get<double>();
    }
  } else if constexpr (std::same_as<T, std::optional<std::string>>) {
    if (!in.is_string()) wrong_type(key);
    value = in.get<std::string>();
  } else if constexpr (std::same_as<T, ModelState>) {
    const auto state = in.is_string() ? model_state_from_string(in.get<std::string>()) : std::nullopt;
    if (!state) wrong_type(key);
    value = *state;
  } else if constexpr (std::same_as<T, json>) {
    value = in;
  } else if constexpr (Record<T>) {
    value = from_object<T>(in, key);
  } else {
    if (!in.is_array()) wrong_type(key);
    value.clear();
    for (const json& item : in) {
      typename T::value_type element{};
      take(item, key, element);
      value.push_back(std::move(element));
    }
  }
}

template <Record T>
T from_object(const json& in, const char* what) {
  if (!in.is_object()) wrong_type(what);
  T record{};
  fields(record, [&in](const char* key, auto& value) {
    if (const auto it = in.find(key); it != in.end()) take(*it, key, value);
  });
  return record;
}

}  // namespace

std::string quote_text(std::string_view text) {
  std::string out = "'";
  for (const char ch : text) {
    const auto byte = static_cast<unsigned char>(ch);
    if (ch == '\'' || ch == '\\') {
      out += '\\';
      out += ch;
    } else if (byte < 0x20 || byte == 0x7f) {
      char escape[8];
      std::snprintf(escape, sizeof escape, "\\u%04x", byte);
      out += escape;
    } else {
      out += ch;  // UTF-8 passes; invalid bytes are replaced when the reply is written
    }
  }
  return out + "'";
}

void check_request_envelope(const json& request) {
  if (!request.is_object()) throw ControlError("request must be a JSON object");
  if (const auto v = request.find("v"); v != request.end()) {
    if (!v->is_number_integer()) throw ControlError("\"v\" must be an integer protocol version");
    if (v->get<long long>() > kProtocolVersion || v->get<long long>() < 1)
      throw ControlError("unsupported protocol version " + v->dump() + " (this daemon speaks " +
                         std::to_string(kProtocolVersion) + ")");
  }
  if (const auto cmd = request.find("cmd"); cmd == request.end() || !cmd->is_string())
    throw ControlError("missing string field \"cmd\"");
}

std::string command_word(const json& request) {
  return request.at("cmd").get<std::string>();
}

json seal_reply(json reply) {
  if (!reply.is_object()) reply = json::object();
  if (!reply.contains("ok")) reply["ok"] = true;
  reply["v"] = kProtocolVersion;
  return reply;
}

json error_reply(std::string_view message) {
  return {{"ok", false}, {"error", std::string(message)}, {"v", kProtocolVersion}};
}

bool reply_ok(const json& reply) {
  if (!reply.is_object()) throw ReplyError("the reply is not an object");
  const auto it = reply.find("ok");
  if (it == reply.end()) return false;
  if (!it->is_boolean()) wrong_type("ok");
  return it->get<bool>();
}

std::string reply_error(const json& reply) {
  if (!reply.is_object()) throw ReplyError("the reply is not an object");
  const auto it = reply.find("error");
  if (it == reply.end()) return "request failed";
  if (!it->is_string()) wrong_type("error");
  return it->get<std::string>();
}

std::string_view to_string(Command command) noexcept {
  switch (command) {
    case Command::kStatus:
      return "status";
    case Command::kGears:
      return "gears";
    case Command::kRetrain:
      return "retrain";
    case Command::kResetModel:
      return "reset-model";
  }
  return "status";
}

std::optional<Command> command_from_string(std::string_view word) noexcept {
  for (const Command c : kCommands)
    if (to_string(c) == word) return c;
  return std::nullopt;
}

json to_json(const Request& request) {
  json out = {{"v", kProtocolVersion}, {"cmd", std::string(to_string(request.command))}};
  if (request.command == Command::kResetModel) {
    if (request.confirm) out["confirm"] = true;
    if (request.keep_samples) out["keep_samples"] = true;
  }
  return out;
}

Request parse_request(const json& request) {
  const std::string word = command_word(request);
  const auto command = command_from_string(word);
  if (!command) {
    std::string known;
    for (const Command c : kCommands)
      known += (known.empty() ? "" : ", ") + std::string(to_string(c));
    throw ControlError("unknown command " + quote_text(word) + " (" + known + ")");
  }
  Request out{.command = *command};
  if (*command == Command::kResetModel) {
    const auto confirm = request.find("confirm");
    if (confirm == request.end() || !confirm->is_boolean() || !confirm->get<bool>())
      throw ControlError("reset-model forgets the learned gears; send \"confirm\": true to do it");
    out.confirm = true;
    const auto keep = request.find("keep_samples");
    if (keep != request.end() && !keep->is_boolean())
      throw ControlError("reset-model: \"keep_samples\" is true or false");
    out.keep_samples = keep != request.end() && keep->get<bool>();
  }
  return out;
}

std::string_view to_string(ModelState state) noexcept {
  return state == ModelState::kTrained ? "trained" : "learning";
}

std::optional<ModelState> model_state_from_string(std::string_view text) noexcept {
  if (text == "trained") return ModelState::kTrained;
  if (text == "learning") return ModelState::kLearning;
  return std::nullopt;
}

json to_json(const StatusReply& reply) {
  return to_object(reply);
}
json to_json(const GearsReply& reply) {
  return to_object(reply);
}
json to_json(const RetrainReply& reply) {
  return to_object(reply);
}
json to_json(const ResetReply& reply) {
  return to_object(reply);
}

StatusReply status_from_json(const json& reply) {
  return from_object<StatusReply>(reply, "the status reply");
}
GearsReply gears_from_json(const json& reply) {
  return from_object<GearsReply>(reply, "the gears reply");
}
RetrainReply retrain_from_json(const json& reply) {
  return from_object<RetrainReply>(reply, "the retrain reply");
}
ResetReply reset_from_json(const json& reply) {
  return from_object<ResetReply>(reply, "the reset-model reply");
}

}  // namespace gearpulse::control
