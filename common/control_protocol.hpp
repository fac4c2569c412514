#pragma once
// The control socket protocol, shared by gearpulsed and gearpulsectl: every command, request field and
// reply field is named here once (docs/interfaces.md is the contract).
// JSON lines over a Unix stream socket: one request object per line, one reply object per line.
//   request: {"v":1,"cmd":"status"}            (also "gears", "retrain", "reset-model" with "confirm":true)
//   reply:   {"v":1,"ok":true,...}  or  {"v":1,"ok":false,"error":"<one line>"}
// "v" may be omitted in a request (taken as the current version); a newer version is refused.
// Reply structs are written by the daemon (to_json) and read by gearpulsectl (from_json). Reading is
// lenient about absent fields (a daemon of the same version may add fields, never remove them; an absent
// field keeps its default) and strict about types: a field of the wrong type throws ReplyError.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

namespace gearpulse::control {

inline constexpr int kProtocolVersion = 1;
// A request line longer than this is refused with an error reply and the connection is closed.
inline constexpr std::size_t kMaxRequestBytes = 4096;

// A request refused: answered {"ok":false,"error":what()}.
struct ControlError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// A reply that does not have the protocol's shape (a field of the wrong type, not an object).
struct ReplyError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Text from a request as an error reply names it: in single quotes, with quotes, backslashes and
// control characters escaped ('st\u0000atus'), so the whole of it shows: a raw NUL would end the message
// (a ControlError's what() is a C string), and raw control bytes would reach the user's terminal.
[[nodiscard]] std::string quote_text(std::string_view text);

// ---- The envelope every request and reply carries.

// Checks "v" (an integer, 1..kProtocolVersion, optional) and "cmd" (a string) of a request object;
// throws ControlError naming what is wrong.
void check_request_envelope(const nlohmann::json& request);
// The command word of a request that passed check_request_envelope().
[[nodiscard]] std::string command_word(const nlohmann::json& request);
// Stamps a handler's reply: "ok" true unless it says otherwise, and the protocol version.
[[nodiscard]] nlohmann::json seal_reply(nlohmann::json reply);
[[nodiscard]] nlohmann::json error_reply(std::string_view message);
[[nodiscard]] bool reply_ok(const nlohmann::json& reply);  // throws ReplyError when "ok" is no boolean
// The error text of a reply that is not ok; throws ReplyError when it is no string.
[[nodiscard]] std::string reply_error(const nlohmann::json& reply);

// ---- Requests.

enum class Command { kStatus, kGears, kRetrain, kResetModel };
inline constexpr Command kCommands[] = {Command::kStatus, Command::kGears, Command::kRetrain,
                                        Command::kResetModel};
[[nodiscard]] std::string_view to_string(Command command) noexcept;
[[nodiscard]] std::optional<Command> command_from_string(std::string_view word) noexcept;

struct Request {
  Command command = Command::kStatus;
  bool confirm = false;       // reset-model: required true
  bool keep_samples = false;  // reset-model: keep the stored training pairs
};
[[nodiscard]] nlohmann::json to_json(const Request& request);
// A request that passed check_request_envelope(); throws ControlError with the reply's error text (an
// unknown command, reset-model without confirm, a field of the wrong type).
[[nodiscard]] Request parse_request(const nlohmann::json& request);

// ---- Replies.

enum class ModelState { kLearning, kTrained };
[[nodiscard]] std::string_view to_string(ModelState state) noexcept;
[[nodiscard]] std::optional<ModelState> model_state_from_string(std::string_view text) noexcept;

struct GearRow {
  int gear = 0;  // 1..M
  double theta = 0.0;
  double std_error = 0.0;
  double weight = 0.0;
};

// A gear the model knows, with the training pairs on its line at its fit and whether a refit kept it
// (docs/cold-start.md).
struct KnownGear {
  int gear = 0;
  double theta = 0.0;
  double std_error = 0.0;
  nlohmann::json pairs;  // the count as the model file gives it, or null
  bool kept = false;
};

struct GearsReply {
  std::vector<GearRow> gears;
  ModelState model_state = ModelState::kLearning;
  nlohmann::json model;  // the model JSON, or null
  std::size_t training_samples = 0;
};

struct RetrainReply {
  bool queued = true;
  std::size_t training_samples = 0;
};

struct ResetReply {
  bool reset = true;
  std::size_t training_samples = 0;
};

struct OutputStatus {
  std::string kind;
  std::string state;
  std::string error;
  std::uint64_t dropped = 0;
  std::uint64_t unheard = 0;
  double pulses_per_km = 0.0;
  std::optional<std::string> path;  // PTY path or chip:line; absent for output none
};

struct GpsStatus {
  std::string state;
  std::optional<double> speed;  // m/s
  int mode = 0;
  std::optional<double> age;  // s
  std::uint64_t reconnects = 0;
  std::uint64_t implausible = 0;
  std::uint64_t unmeasured = 0;
  std::string server;
  std::string error;
};

struct AudioStatus {
  std::string state;
  std::string device;
  unsigned rate = 0;
  std::uint64_t xruns = 0;
  std::uint64_t ring_drops = 0;
  std::string error;
  // While the audio is down (recovering, retrying): the ALSA step that failed last, the attempts to open
  // the device since it went and the last one's wall time; "", 0 and null while a device streams.
  std::string failed_step;
  std::uint64_t open_attempts = 0;
  std::optional<double> last_attempt;  // UNIX seconds
  std::uint64_t reopens = 0;           // lost devices reopened since the capture opened
};

struct TrackerStatus {
  std::optional<double> freq;  // Hz
  std::optional<double> snr_db;
  bool confident = false;
  std::uint64_t turns = 0;      // wake-ups of the tracker thread since the daemon started
  std::uint64_t late_hops = 0;  // hops stepped after a backlog, on the GPS of their due time
};

struct LearningStatus {
  bool young = false;
  double moving_time = 0.0;
  std::optional<double> next_refit;
  std::size_t cluster_pairs = 0;
  std::size_t first_fit_pairs = 0;
};

struct ModelStatus {
  ModelState state = ModelState::kLearning;
  std::size_t gears = 0;
  std::size_t fit_samples = 0;
  std::size_t training_samples = 0;
  std::size_t new_samples = 0;
  std::uint64_t retrain_runs = 0;
  bool retrain_busy = false;
  std::optional<double> last_retrain;  // UNIX seconds
  std::string last_result;
  std::optional<std::string> reason;  // why a model has no gears, only then
  std::vector<KnownGear> known_gears;
  LearningStatus learning;
  std::vector<std::string> problems;
};

struct ConfigStatus {
  std::string file;
  std::string reload_error;
  std::vector<std::string> restart_pending;
};

struct ThreadStatus {
  std::vector<std::string> stalled;
  std::vector<std::string> missing;
  std::vector<std::string> realtime_refused;
};

struct StatusReply {
  double speed = 0.0;  // m/s
  double speed_kmh = 0.0;
  double speed_sd = 0.0;  // m/s: the synthesis' spread about `speed` through an outage, 0 on GPS
  std::string source;
  int gear = 0;
  std::uint64_t pulses = 0;
  double pulse_frequency = 0.0;
  std::vector<GearRow> gears;
  ModelState model_state = ModelState::kLearning;
  std::size_t training_samples = 0;
  double uptime = 0.0;
  OutputStatus output;
  GpsStatus gps;
  AudioStatus audio;
  TrackerStatus tracker;
  ModelStatus model;
  ConfigStatus config;
  ThreadStatus threads;
  std::size_t clients = 0;
};

[[nodiscard]] nlohmann::json to_json(const StatusReply& reply);
[[nodiscard]] nlohmann::json to_json(const GearsReply& reply);
[[nodiscard]] nlohmann::json to_json(const RetrainReply& reply);
[[nodiscard]] nlohmann::json to_json(const ResetReply& reply);
// Throw ReplyError for a reply of another shape.
[[nodiscard]] StatusReply status_from_json(const nlohmann::json& reply);
[[nodiscard]] GearsReply gears_from_json(const nlohmann::json& reply);
[[nodiscard]] RetrainReply retrain_from_json(const nlohmann::json& reply);
[[nodiscard]] ResetReply reset_from_json(const nlohmann::json& reply);

// A number for the wire, or null when it is not available (or not finite).
[[nodiscard]] inline std::optional<double> number_if(double value, bool available) {
  return available && std::isfinite(value) ? std::optional<double>(value) : std::nullopt;
}

}  // namespace gearpulse::control
