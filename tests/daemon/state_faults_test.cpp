// Faults of the state directory a user can act on: a model save that keeps failing is said once and
// listed in status, a corrupt model.json that cannot be set aside does not stop the model being saved,
// and the log lines of a state directory that cannot be written say what to check.
#include <catch2/catch.hpp>

#include <atomic>
#include <filesystem>
#include <span>
#include <stop_token>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/control_handler.hpp"
#include "daemon/model_store.hpp"
#include "daemon/retrainer.hpp"
#include "daemon/state_directory.hpp"
#include "daemon/training_store.hpp"
#include "tests/daemon/log_lines.hpp"
#include "tests/daemon/persistence_fixtures.hpp"
#include "tests/test_util.hpp"

using namespace gearpulse;
using namespace gearpulse::daemon;
using gearpulse::test::add_pairs;
using gearpulse::test::LogLines;
using gearpulse::test::read_text;
using gearpulse::test::TempDir;
using gearpulse::test::three_gears;
using gearpulse::test::write_text;

namespace {

Retrainer::Fitter three_gear_fitter() {
  return [](std::span<const Sample>, std::stop_token) { return three_gears(); };
}

bool any_contains(const std::vector<std::string>& lines, const std::string& text) {
  for (const auto& line : lines)
    if (line.find(text) != std::string::npos) return true;
  return false;
}

}  // namespace

// On a full or read-only disk every retrain fails to save the same way: the journal got a line per retrain
// and status only the last retrain's result, which the next one overwrote.
TEST_CASE("daemon: a model save that keeps failing is said once, listed in status, and its end said") {
  TempDir dir;
  write_text(dir / "state", "a file where the state directory goes\n");  // every save fails, for root too
  TrainingStore store(1e9, 10000);
  add_pairs(store, 0, 20);
  ModelHolder model;
  Retrainer retrainer(store, model, dir / "state" / "model.json", three_gear_fitter(), {});
  LogLines log;
  for (int i = 0; i < 3; ++i)
    REQUIRE(retrainer.retrain_now());
  CHECK(log.levels("cannot save") == std::vector{spdlog::level::err});
  CHECK(log.count("model.state_dir") == 1);  // what to check
  CHECK(log.count("/var/lib/gearpulse") == 1);
  const Retrainer::Status failing = retrainer.status();
  CHECK(failing.last_result.find("; not saved: ") != std::string::npos);
  CHECK(failing.save_problem.find("cannot save model.json: ") == 0);
  const Config config;
  StatusInputs in{.config = config,
                  .config_path = "gearpulse.toml",
                  .pipeline = {},
                  .model = model.get(),
                  .retrainer = failing,
                  .training_samples = 20,
                  .new_samples = 0,
                  .problems = {"training.bin discarded"},
                  .reload_error = "",
                  .restart_pending = {},
                  .clients = 0,
                  .uptime = 1.0};
  CHECK(status_reply(in).model.problems ==
        std::vector<std::string>{"training.bin discarded", failing.save_problem});

  std::filesystem::remove(dir / "state");
  std::filesystem::create_directory(dir / "state");
  REQUIRE(retrainer.retrain_now());
  CHECK(log.levels("saved again") == std::vector{spdlog::level::info});
  CHECK(retrainer.status().save_problem.empty());
  CHECK(model_file_holds(dir / "state" / "model.json", *model.get()));
  in.retrainer = retrainer.status();
  CHECK(status_reply(in).model.problems == std::vector<std::string>{"training.bin discarded"});
}

// A model.json installed while the daemon runs stays, and every retrain finds it there: said once too.
TEST_CASE("daemon: a model.json replaced while the daemon runs is said once, not at every retrain") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  add_pairs(store, 0, 20);
  ModelHolder model;
  Retrainer retrainer(store, model, dir / "model.json", three_gear_fitter(), {});
  REQUIRE(retrainer.retrain_now());
  GearModel installed = three_gears();
  installed.samples = 999;
  save_model_file(dir / "model.json", installed);
  LogLines log;
  for (int i = 0; i < 3; ++i)
    REQUIRE(retrainer.retrain_now());
  CHECK(log.levels("was replaced while gearpulsed ran") == std::vector{spdlog::level::warn});
  CHECK(model_file_holds(dir / "model.json", installed));
  CHECK(retrainer.status().save_problem.find("replaced by another program") != std::string::npos);
  // A reset removes model.json: the problem with it is over.
  retrainer.model_file_removed();
  CHECK(retrainer.status().save_problem.empty());
}

// Every name to set a corrupt model.json aside as is taken: the file stayed, the daemon had not loaded
// it, and every save took it for one installed by a user and left it, so nothing learned was ever saved
// (and the log blamed another program).
TEST_CASE("daemon: a corrupt model.json that cannot be set aside is said, and the model's saves replace it") {
  TempDir dir;
  write_text(dir / "model.json", "{\"version\": 1, \"gears\": [");
  write_text(dir / "model.json.corrupt", "an older corruption\n");
  for (int n = 1; n < 100; ++n)
    write_text(dir / ("model.json.corrupt." + std::to_string(n)), "an older corruption\n");
  TrainingStore store(1e9, 10000);
  ModelHolder model;
  StateDirectory state(dir.path(), model, store, 10000);
  LogLines log;
  REQUIRE(state.load());
  add_pairs(store, 0, 20);
  CHECK(log.count("delete it to let gearpulsed save its model") == 1);
  CHECK(log.count("100 copies are set aside already") == 1);
  CHECK(any_contains(state.problems(), "model.json ignored: model: not valid JSON at line 1"));
  CHECK(any_contains(state.problems(), "the model's saves replace it"));

  Retrainer retrainer(store, model, state.model_path(), three_gear_fitter(), {});
  REQUIRE(retrainer.retrain_now());
  INFO(retrainer.status().last_result);
  CHECK(retrainer.status().last_result.find("not saved") == std::string::npos);
  CHECK(model_file_holds(state.model_path(), *model.get()));
  CHECK(read_text(dir / "model.json.corrupt.99") == "an older corruption\n");
}

TEST_CASE("daemon: a state directory that cannot be made or saved in says what to check") {
  TempDir dir;
  write_text(dir / "blocker", "not a directory\n");
  TrainingStore store(1e9, 10000);
  ModelHolder model;
  StateDirectory state(dir / "blocker" / "state", model, store, 10000);
  LogLines log;
  REQUIRE(state.load());
  add_pairs(store, 0, 20);
  CHECK_FALSE(state.save_store("periodic"));
  for (const char* what : {"state: cannot create", "training: cannot save"}) {
    INFO(what);
    CHECK(log.count(what) == 1);
  }
  CHECK(log.count("check that model.state_dir (" + (dir / "blocker" / "state").string() + ")") == 2);
  CHECK(log.count("under the systemd unit (ProtectSystem=strict) only /var/lib/gearpulse is writable") == 2);
  // Status keeps the fault itself, short.
  CHECK_FALSE(any_contains(state.problems(), "model.state_dir"));
}
