#pragma once
// The daemon's side of the control protocol (common/control_protocol.hpp): what each command does and
// the reply it gets. The socket itself is the ControlServer's.
#include <chrono>
#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/control_protocol.hpp"
#include "daemon/config.hpp"
#include "daemon/log_limiter.hpp"
#include "daemon/model_store.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/retrainer.hpp"
#include "daemon/state_directory.hpp"
#include "daemon/training_store.hpp"

namespace gearpulse::daemon {

// What a status reply is made of, gathered by the daemon when it is asked.
struct StatusInputs {
  const Config& config;
  std::string config_path;
  PipelineSnapshot pipeline;
  ModelPtr model;
  Retrainer::Status retrainer;
  std::size_t training_samples = 0;
  std::size_t new_samples = 0;
  std::vector<std::string> problems;  // the state directory's
  std::string reload_error;           // the last SIGHUP's file was refused ("" = it was taken)
  std::vector<std::string> restart_pending;
  std::size_t clients = 0;
  double uptime = 0.0;  // s
};

[[nodiscard]] control::StatusReply status_reply(const StatusInputs& in);
[[nodiscard]] control::GearsReply gears_reply(const ModelPtr& model, std::size_t training_samples);

class ControlHandler {
 public:
  using StatusSource = std::function<control::StatusReply()>;
  ControlHandler(ModelHolder& model, TrainingStore& store, Retrainer& retrainer, StateDirectory& state,
                 StatusSource status)
      : model_(model), store_(store), retrainer_(retrainer), state_(state), status_(std::move(status)) {}

  // The ControlServer's handler: answers one request that passed the envelope's checks. Throws
  // ControlError for a request refused.
  nlohmann::json operator()(const nlohmann::json& request) const;

 private:
  ModelHolder& model_;
  TrainingStore& store_;
  Retrainer& retrainer_;
  StateDirectory& state_;
  StatusSource status_;
  // The info and warning lines of requests (a client in a loop must not push the daemon's real warnings
  // out of the log queue): one per command every 10 s, with how many came since.
  std::shared_ptr<LogLimiter> request_lines_ = std::make_shared<LogLimiter>(std::chrono::seconds(10));
};

}  // namespace gearpulse::daemon
