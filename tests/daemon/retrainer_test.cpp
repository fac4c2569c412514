// The retrainer: when it fits, what it installs and saves, what it says of a fit, how it stops, and the
// fit's own thread at low priority.
#include <catch2/catch.hpp>

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <memory>
#include <stdexcept>
#include <stop_token>
#include <string>
#include <thread>
#include <vector>

#include "core/estimator.hpp"
#include "daemon/fitter.hpp"
#include "daemon/model_store.hpp"
#include "daemon/retrainer.hpp"
#include "daemon/training_store.hpp"
#include "tests/daemon/log_lines.hpp"
#include "tests/daemon/persistence_fixtures.hpp"
#include "tests/test_util.hpp"
#include "tools/sim/vehicle_sim.hpp"

using namespace gearpulse;
using namespace gearpulse::daemon;
using gearpulse::test::add_pairs;
using gearpulse::test::pair_time;
using gearpulse::test::TempDir;
using gearpulse::test::three_gears;

namespace {

// A fitter that counts its calls in `fits` and finds three gears.
Retrainer::Fitter counting_fitter(std::atomic<int>& fits) {
  return [&fits](std::span<const Sample>, std::stop_token) {
    ++fits;
    return three_gears();
  };
}

// A fitter that finds three gears and says it used `samples` pairs (read at each fit).
Retrainer::Fitter fitter_on(const std::size_t& samples) {
  return [&samples](std::span<const Sample>, std::stop_token) {
    GearModel m = three_gears();
    m.samples = samples;
    return m;
  };
}

// Waits up to 20 s for a first fit: the fits here take no time, but the retrainer runs them at the lowest
// priority (SCHED_IDLE), which a loaded machine serves last. The bound is for a failing test only.
void wait_for_a_fit(const std::atomic<int>& fits) {
  for (int i = 0; i < 2000 && fits.load() == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
}

}  // namespace

TEST_CASE("daemon: retrainer swaps in and saves a fitted model") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 20; ++i)
    store.add({double(i), 10.0, 100.0});
  ModelHolder model;
  std::size_t seen = 0;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample> s, std::stop_token) {
                        seen = s.size();
                        return three_gears();
                      },
                      {});
  const auto wall = [] {
    return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  };
  const double before = wall();
  CHECK(retrainer.retrain_now());
  // Status says when the model was last retrained (gearpulsectl's "last retrain").
  CHECK(retrainer.status().runs == 1);
  CHECK(retrainer.status().last_run_wall >= std::floor(before));
  CHECK(retrainer.status().last_run_wall <= wall() + 1.0);
  CHECK(seen == 20);
  REQUIRE(model.trained());
  CHECK(model.get()->gears.size() == 3);
  const ModelLoad saved = load_model_file(dir / "model.json");
  REQUIRE(saved.model != nullptr);
  CHECK(store.new_samples() == 0);
  CHECK(retrainer.status().accepted == 1);
  // The newest pair it saw is kept with the model: at the next start, pairs after it are new.
  CHECK(saved.model->extra.value(std::string(kTrainedUntil), -1.0) == 19.0);
  add_pairs(store, 20, 26);
  TrainingStore next_start(1e9, 10000);
  REQUIRE(next_start.deserialize(store.serialize()).empty());
  CHECK(next_start.new_samples() == 0);
  next_start.set_new_after(saved.model->extra.value(std::string(kTrainedUntil), -1.0));
  CHECK(next_start.new_samples() == 6);
}

TEST_CASE("daemon: a retrain that found the GPS speeds late against the engine says gps.latency is off") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 20; ++i)
    store.add({double(i), 10.0, 100.0});
  ModelHolder model;
  double lag = 0.0;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token) {
                        GearModel m = three_gears();
                        m.extra["speed_lag"] = lag;
                        return m;
                      },
                      {});
  CHECK(retrainer.retrain_now());
  CHECK(retrainer.status().last_result.find("gps.latency") == std::string::npos);
  lag = 0.05;  // within what the search resolves at 1 Hz: not worth a word
  store.add({19.5, 10.0, 100.0});
  CHECK(retrainer.retrain_now());
  CHECK(retrainer.status().last_result.find("gps.latency") == std::string::npos);
  lag = 0.375;  // the fit paired each engine reading with the speed stamped 0.375 s after it
  store.add({20.0, 10.0, 100.0});
  CHECK(retrainer.retrain_now());
  CHECK(retrainer.status().last_result.find("gps.latency may be 0.38 s too short") != std::string::npos);
  CHECK(retrainer.status().last_result.find("describe the engine 0.38 s before their stamps") !=
        std::string::npos);
  lag = -0.5;
  store.add({21.0, 10.0, 100.0});
  CHECK(retrainer.retrain_now());
  CHECK(retrainer.status().last_result.find("gps.latency may be 0.50 s too long") != std::string::npos);
  CHECK(retrainer.status().last_result.find("describe the engine 0.50 s after their stamps") !=
        std::string::npos);
}

TEST_CASE(
    "daemon: pairs stamped with a gps.latency shorter than the receiver's are reported by the retrain") {
  // As the pipeline pairs them: a fix received at rx is stamped rx - gps.latency and paired with the engine
  // frequency at that stamp. The receiver reports 0.5 s after the instant it describes, the config says
  // 0: each pair holds the engine at t and the speed of t - 0.5 s.
  const sim::Vehicle car = sim::vehicle_preset("hatch-5");
  sim::ObservationOptions ten_hz;
  ten_hz.period = 0.1;
  const auto observed = sim::simulate_observations(car, sim::DrivingStyle::kUrban, 2400.0, 1, 7, ten_hz);
  constexpr std::size_t kLateRows = 5;  // 0.5 s
  TempDir dir;
  TrainingStore store(1e9, 100000);
  for (std::size_t k = kLateRows; k < observed.size(); ++k)
    store.add({observed[k].truth.t, observed[k - kLateRows].speed, observed[k].freq});
  ModelHolder model;
  Retrainer retrainer(store, model, dir / "model.json",
                      [](std::span<const Sample> s, std::stop_token) { return fit_gear_model(s, {}).model; },
                      {});
  CHECK(retrainer.retrain_now());
  INFO(retrainer.status().last_result);
  const std::string& said = retrainer.status().last_result;
  const auto at = said.find("gps.latency may be ");
  REQUIRE(at != std::string::npos);
  CHECK(std::stod(said.substr(at + 19)) == Approx(0.5).margin(0.03));
  CHECK(said.find("s too short") != std::string::npos);
}

TEST_CASE("daemon: retrainer fits at start when the store holds enough pairs its model has not seen") {
  // Trips shorter than the retrain interval: the pairs gathered over several of them are learned from at
  // the next start, not never.
  TempDir dir;
  TrainingStore store(1e9, 10000);
  add_pairs(store, 0, 50);
  ModelHolder model;
  model.set(std::make_shared<const GearModel>(three_gears()));
  std::atomic<int> fits{0};
  const auto fitter = [&](std::span<const Sample>, std::stop_token) {
    ++fits;
    return three_gears();
  };
  const Retrainer::Settings settings{std::chrono::duration<double>(3600.0), 30};
  SECTION("enough new pairs") {
    store.set_new_after(pair_time(10));  // 39 newer than the model's fit
    Retrainer retrainer(store, model, dir / "model.json", fitter, settings);
    retrainer.start();
    wait_for_a_fit(fits);
    retrainer.stop();
    CHECK(fits.load() == 1);
  }
  SECTION("too few: it waits for the interval") {
    store.set_new_after(pair_time(25));  // 24 newer
    Retrainer retrainer(store, model, dir / "model.json", fitter, settings);
    retrainer.start();
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    retrainer.stop();
    CHECK(fits.load() == 0);
  }
}

TEST_CASE("daemon: an empty or failed fit never replaces a good model") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  store.add({1.0, 10.0, 100.0});
  ModelHolder model;
  const auto good = std::make_shared<const GearModel>(three_gears());
  model.set(good);
  int calls = 0;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token) -> GearModel {
                        if (++calls == 1) {
                          GearModel none;
                          none.reason = "no discrete ladder";
                          return none;
                        }
                        throw std::runtime_error("optimizer diverged");
                      },
                      {});
  CHECK_FALSE(retrainer.retrain_now());
  CHECK(model.get() == good);
  CHECK(retrainer.status().last_result.find("no discrete ladder") != std::string::npos);
  store.add({2.0, 10.0, 100.0});
  CHECK_FALSE(retrainer.retrain_now());
  CHECK(model.get() == good);
  CHECK(retrainer.status().last_result.find("optimizer diverged") != std::string::npos);
  // The pairs a failed fit saw count as tried: the retrainer waits for new ones instead of failing on
  // the same pairs at every interval.
  CHECK(store.new_samples() == 0);
  CHECK_FALSE(std::filesystem::exists(dir / "model.json"));
}

TEST_CASE("daemon: a retrain with no training pairs yet says so and runs no fit") {
  // A `retrain` right after a reset: the user reads that there is nothing to learn from, not a fit on no
  // pairs that "found no gear ladder".
  TempDir dir;
  TrainingStore store(1e9, 10000);
  ModelHolder model;
  std::atomic<int> fits{0};
  Retrainer retrainer(store, model, dir / "model.json", counting_fitter(fits), {});
  CHECK_FALSE(retrainer.retrain_now());
  CHECK(fits.load() == 0);
  CHECK_FALSE(model.trained());
  CHECK(retrainer.status().last_result == "no training samples yet");
  CHECK(retrainer.status().runs == 1);
  CHECK(retrainer.status().accepted == 0);
}

TEST_CASE("daemon: a fit that again finds no gear ladder is noted, not warned about at every retrain") {
  // An automatic answers "no ladder" at every retrain interval; the log at 2 a.m. should say so once.
  TempDir dir;
  TrainingStore store(1e9, 10000);
  store.add({1.0, 10.0, 100.0});
  ModelHolder model;
  bool ladder = false;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token) -> GearModel {
                        if (ladder) return three_gears();
                        GearModel none;
                        none.reason = "no discrete ladder";
                        return none;
                      },
                      {});
  gearpulse::test::LogLines log;
  const auto levels_of_ladder_lines = [&] { return log.levels("no gear ladder"); };
  retrainer.retrain_now();
  retrainer.retrain_now();
  retrainer.retrain_now();
  const auto first = levels_of_ladder_lines();
  ladder = true;
  retrainer.retrain_now();
  ladder = false;
  retrainer.retrain_now();
  const auto after = levels_of_ladder_lines();
  using L = spdlog::level::level_enum;
  CHECK(first == std::vector<L>{L::warn, L::info, L::info});
  // Once a fit found a ladder, losing it again is news.
  CHECK(after == std::vector<L>{L::warn, L::info, L::info, L::warn});
  CHECK(retrainer.status().last_result.find("no discrete ladder") != std::string::npos);
}

TEST_CASE("daemon: a fit begun before a model reset is discarded, not installed over the reset") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  store.add({1.0, 10.0, 100.0});
  ModelHolder model;
  model.set(std::make_shared<const GearModel>(three_gears()));
  int fits = 0;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token) {
                        if (++fits == 1) {
                          // reset-model arrives while the first fit runs (as the control thread does it)
                          const auto lock = model.lock_writes();
                          model.set(nullptr);
                        }
                        return three_gears();
                      },
                      {});
  CHECK_FALSE(retrainer.retrain_now());
  CHECK(model.get() == nullptr);
  CHECK_FALSE(std::filesystem::exists(dir / "model.json"));
  CHECK(retrainer.status().last_result.find("discarded") != std::string::npos);
  // The next fit, begun after the reset, is installed.
  CHECK(retrainer.retrain_now());
  CHECK(model.trained());
}

// A reset that clears the pairs while a fit runs, with pairs added after it: they are newer than any
// fit, and stay new. The fit's count of new pairs, read before the clear, was taken off them.
TEST_CASE("daemon: pairs added after a clear during a fit stay new") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 700; ++i)
    store.add({1.0 + i, 10.0, 100.0});
  ModelHolder model;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token) {
                        store.clear();  // reset-model --confirm while the fit runs, then driving on
                        for (int i = 0; i < 300; ++i)
                          store.add({2000.0 + i, 10.0, 100.0});
                        return three_gears();
                      },
                      {});
  (void)retrainer.retrain_now();
  CHECK(store.new_samples() == 300);
}

TEST_CASE("daemon: retrainer thread fits when asked and stops promptly") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 5; ++i)
    store.add({double(i), 10.0, 100.0});
  ModelHolder model;
  std::atomic<int> fits{0};
  Retrainer retrainer(store, model, dir / "model.json", counting_fitter(fits),
                      {std::chrono::duration<double>(3600.0), 1000});
  retrainer.start();
  retrainer.request();
  wait_for_a_fit(fits);
  retrainer.stop();
  CHECK(fits.load() == 1);
  CHECK(model.trained());
}

TEST_CASE("daemon: stopping the retrainer cancels a fit under way and keeps its pairs new") {
  // A fit under SCHED_IDLE on a CPU others keep busy can take minutes; a SIGTERM must not wait for it.
  TempDir dir;
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 5; ++i)
    store.add({double(i), 10.0, 100.0});
  ModelHolder model;
  std::atomic<bool> fitting{false};
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token stop) -> GearModel {
                        fitting = true;
                        // A long fit: its passes over the pairs end when a stop is asked for.
                        const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(30);
                        while (std::chrono::steady_clock::now() < give_up) {
                          if (stop.stop_requested()) throw FitCancelled();
                          std::this_thread::sleep_for(std::chrono::milliseconds(5));
                        }
                        return three_gears();
                      },
                      {std::chrono::duration<double>(3600.0), 1000});
  retrainer.start();
  retrainer.request();
  for (int i = 0; i < 2000 && !fitting; ++i)  // 20 s: the fit thread runs at SCHED_IDLE
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  REQUIRE(fitting);
  const auto t0 = std::chrono::steady_clock::now();
  retrainer.stop();
  // Not the fit's 30 s: a third of it is room for the SCHED_IDLE fit thread to be served on a loaded
  // machine and see the stop at its next pass.
  CHECK(std::chrono::steady_clock::now() - t0 < std::chrono::seconds(10));
  CHECK_FALSE(model.trained());
  CHECK(retrainer.status().last_result.find("cancelled") != std::string::npos);
  CHECK_FALSE(retrainer.status().busy);
  CHECK(store.new_samples() == 5);  // the next start fits them
}

TEST_CASE("daemon: the estimator's fit ends with FitCancelled once a stop is requested") {
  std::vector<Sample> pairs;
  for (int i = 0; i < 600; ++i)  // two gears' lines
    pairs.push_back({double(i), 5.0 + 0.01 * i, (i % 2 ? 40.0 : 25.0) + 0.02 * i});
  std::stop_source stop;
  stop.request_stop();
  CHECK_THROWS_AS(make_estimator_fitter()(pairs, stop.get_token()), FitCancelled);
  FitOptions paper;
  paper.ratios = {1.4, 1.5};
  paper.stop = stop.get_token();
  CHECK_THROWS_AS(fit_gear_model(pairs, paper), FitCancelled);
  CHECK_NOTHROW(make_estimator_fitter()(pairs, {}));
}

TEST_CASE("daemon: a retrain interval shortened while the retrainer waits applies at once") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  ModelHolder model;
  std::atomic<int> fits{0};
  Retrainer retrainer(store, model, dir / "model.json", counting_fitter(fits),
                      {std::chrono::duration<double>(3600.0), 5});
  retrainer.start();  // nothing to learn from at start: it waits an hour
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  for (int i = 0; i < 10; ++i)
    store.add({double(i), 10.0, 100.0});
  // As a reload sets it: the wait under way ends at the new interval, not the old one.
  Retrainer::Settings shorter = retrainer.settings();
  shorter.interval = std::chrono::duration<double>(0.2);
  retrainer.set_settings(shorter);
  wait_for_a_fit(fits);
  retrainer.stop();
  CHECK(fits.load() >= 1);
}

TEST_CASE("daemon: the fit runs in a thread of its own at low priority, the rest at the caller's") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 5; ++i)
    store.add({double(i), 10.0, 100.0});
  ModelHolder model;
  std::thread::id fit_thread;
  int fit_nice = 0;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token) {
                        fit_thread = std::this_thread::get_id();
                        errno = 0;
                        fit_nice = ::getpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid)));
                        return three_gears();
                      },
                      {std::chrono::duration<double>(600.0), 1});
  errno = 0;
  const int caller_nice = ::getpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid)));
  CHECK(retrainer.retrain_now());
  CHECK(fit_thread != std::this_thread::get_id());
  CHECK(fit_nice == 19);
  // The caller (who takes the store's copy and installs and saves the model) keeps its priority.
  CHECK(::getpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid))) == caller_nice);
  // A fit that throws is reported as it was on the caller's thread.
  Retrainer failing(
      store, model, dir / "model.json",
      [](std::span<const Sample>, std::stop_token) -> GearModel { throw std::runtime_error("no memory"); },
      {std::chrono::duration<double>(600.0), 1});
  CHECK_FALSE(failing.retrain_now());
  CHECK(failing.status().last_result.find("no memory") != std::string::npos);
  // Nor may a fit that throws something other than a std::exception end the retrainer's thread (and with
  // it the daemon): it is a failed fit, the model kept.
  Retrainer odd(store, model, dir / "model.json",
                [](std::span<const Sample>, std::stop_token) -> GearModel { throw 42; },
                {std::chrono::duration<double>(600.0), 1});
  CHECK_FALSE(odd.retrain_now());
  CHECK(odd.status().last_result.find("fit failed") != std::string::npos);
  CHECK_FALSE(odd.status().busy);
}

TEST_CASE("daemon: a fit on few samples does not replace a model learned on many") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  store.add({1.0, 10.0, 100.0});
  ModelHolder model;
  GearModel big = three_gears();
  big.samples = 50'000;
  const auto good = std::make_shared<const GearModel>(big);
  model.set(good);
  std::size_t fitted_samples = 100;
  Retrainer retrainer(store, model, dir / "model.json", fitter_on(fitted_samples),
                      {std::chrono::duration<double>(600.0), 1, 3600});
  CHECK_FALSE(retrainer.retrain_now());
  CHECK(model.get() == good);
  fitted_samples = 3600;
  CHECK(retrainer.retrain_now());
  CHECK(model.get()->samples == 3600);
  // Without a model any ladder is better than none.
  model.set(nullptr);
  fitted_samples = 10;
  CHECK(retrainer.retrain_now());
  CHECK(model.get()->samples == 10);
}

// A model fitted on more pairs than the store can hold (by `gearpulse fit` on days of logs, or before the
// store's limits were lowered) was never replaced: no fit could reach its count.
TEST_CASE("daemon: a fit on every pair the store can hold replaces a model fitted on more") {
  TempDir dir;
  TrainingStore store(1e9, 1000);
  for (int i = 0; i < 1000; ++i)
    store.add({1.0 + i, 10.0, 100.0});
  ModelHolder model;
  GearModel big = three_gears();
  big.samples = 2401;
  model.set(std::make_shared<const GearModel>(big));
  std::size_t fitted_samples = 999;
  Retrainer retrainer(store, model, dir / "model.json", fitter_on(fitted_samples),
                      {std::chrono::duration<double>(600.0), 1, 3600});
  CHECK_FALSE(retrainer.retrain_now());
  CHECK(model.get()->samples == 2401);
  fitted_samples = 1000;
  CHECK(retrainer.retrain_now());
  CHECK(model.get()->samples == 1000);
  // Held by its hours (store_hours), at a pair a second, the same.
  store.set_limits(600.0, 100000);
  model.set(std::make_shared<const GearModel>(big));
  fitted_samples = 600;
  CHECK(retrainer.retrain_now());
  CHECK(model.get()->samples == 600);
}
