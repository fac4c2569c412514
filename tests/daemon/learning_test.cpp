// The learning schedule of a young model, the fit on few pairs, and the rule that keeps learned gears.
#include <catch2/catch.hpp>

#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <random>
#include <span>
#include <thread>
#include <vector>

#include "core/estimator.hpp"
#include "daemon/fitter.hpp"
#include "daemon/learning_schedule.hpp"
#include "daemon/retrainer.hpp"
#include "daemon/training_store.hpp"
#include "tests/test_util.hpp"
#include "tools/sim/vehicle_sim.hpp"

using namespace gearpulse;
using namespace gearpulse::daemon;
using gearpulse::test::TempDir;
using gearpulse::test::write_text;

namespace {

// Pairs at 1 Hz of a car driven in the given gears only, in turn, each for 25-45 s: the revs climb from
// 1.4x idle to the upshift point and back (a driver accelerating and easing off), the clutch out for 2 s
// between gears (revs falling toward idle at an unchanged speed). GPS noise 0.05 m/s, tracker 0.2 Hz.
std::vector<Sample> drive_in_gears(const std::vector<double>& thetas, double seconds, std::uint32_t seed,
                                   double t0 = 0.0) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> speed_noise(0.0, 0.05), freq_noise(0.0, 0.2);
  std::uniform_real_distribution<double> length(25.0, 45.0), phase(0.0, 6.3);
  constexpr double kIdle = 13.3, kLow = 1.4 * kIdle, kHigh = 42.0;
  std::vector<Sample> out;
  double t = t0;
  std::size_t turn = 0;
  while (t < t0 + seconds) {
    const double theta = thetas[turn++ % thetas.size()];
    const double end = t + length(rng);
    const double p = phase(rng);
    double v = 0.0;
    for (; t < end && t < t0 + seconds; t += 1.0) {
      const double f = kLow + (kHigh - kLow) * 0.5 * (1.0 + std::sin(p + 0.15 * (t - t0)));
      v = theta * f;
      out.push_back({t, v + speed_noise(rng), f + freq_noise(rng)});
    }
    for (int k = 0; k < 2; ++k, t += 1.0)  // declutched: the speed holds, the revs fall
      out.push_back({t, v + speed_noise(rng), kIdle * 1.3 + freq_noise(rng)});
  }
  return out;
}

const std::vector<double>& hatch_thetas() {
  static const std::vector<double> thetas = sim::vehicle_preset("hatch-5").theta;
  return thetas;
}

}  // namespace

TEST_CASE("learning: the schedule fits on a clear gear, then after 1, 2, 4, 8, 16 minutes of moving") {
  LearningSchedule schedule;  // defaults: 40 pairs, 60 s, 960 s
  PairsSummary pairs;
  pairs.moving_time = 20.0;
  pairs.largest_cluster = 39;
  CHECK(schedule.young(pairs, false));
  CHECK_FALSE(schedule.due(pairs, false));
  pairs.moving_time = 45.0;
  pairs.largest_cluster = 40;
  REQUIRE(schedule.due(pairs, false));
  schedule.tried(pairs);
  CHECK(schedule.next_refit(45.0) == Approx(60.0));
  // With the model that fit gave, the refits follow moving time.
  std::vector<double> fits;
  for (double m = 46.0; m <= 1200.0; m += 1.0) {
    pairs.moving_time = m;
    if (schedule.due(pairs, true)) {
      fits.push_back(m);
      schedule.tried(pairs);
    }
  }
  CHECK(fits == std::vector<double>{60.0, 120.0, 240.0, 480.0, 960.0});
  CHECK_FALSE(schedule.young(pairs, true));
  CHECK_FALSE(schedule.next_refit(pairs.moving_time).has_value());
}

TEST_CASE("learning: without a model a fit that found nothing is tried again only as the gear's pairs grow") {
  LearningSchedule schedule;
  PairsSummary pairs{30.0, 40};
  REQUIRE(schedule.due(pairs, false));
  schedule.tried(pairs);  // no ladder
  pairs = {35.0, 55};
  CHECK_FALSE(schedule.due(pairs, false));
  pairs = {40.0, 60};  // half the first fit's count more
  CHECK(schedule.due(pairs, false));
  schedule.tried(pairs);
  pairs = {61.0, 61};  // or a refit time passed
  CHECK(schedule.due(pairs, false));
  // An automatic never shows a cluster: past the schedule the interval rule alone decides.
  pairs = {960.0, 10};
  CHECK_FALSE(schedule.young(pairs, false));
  CHECK_FALSE(schedule.due(pairs, false));
  LearningSchedule off({40, 60.0, 0.0});
  CHECK_FALSE(off.young({10.0, 100}, false));
  CHECK_FALSE(off.due({10.0, 100}, false));
}

TEST_CASE("learning: a young model is refitted as soon as the pairs show a gear it lacks") {
  const std::vector<double>& th = hatch_thetas();
  std::vector<Sample> pairs = drive_in_gears({th[1]}, 70.0, 8);
  const GearModel one = make_estimator_fitter()(pairs, {});
  REQUIRE(one.gears.size() == 1);
  LearningSchedule schedule;
  PairsSummary s = summarize_pairs(pairs, &one);
  CHECK(s.model_gears == 1);
  CHECK(s.new_gear_cluster < 10);  // all of them on the model's line
  schedule.tried(s);
  // 3rd gear for 12 s, before the next refit time (120 s of moving).
  std::vector<Sample> third = drive_in_gears({th[2]}, 12.0, 9, pairs.back().t + 1.0);
  third.resize(12);  // without the clutch-out seconds
  pairs.insert(pairs.end(), third.begin(), third.end());
  s = summarize_pairs(pairs, &one);
  REQUIRE(s.moving_time < 120.0);
  CHECK(s.largest_cluster > 40);
  CHECK(s.new_gear_cluster >= 10);
  CHECK(schedule.due(s, true));
  schedule.tried(s);  // a fit that did not add it: tried again once 10 more show
  CHECK_FALSE(schedule.due(s, true));
}

TEST_CASE("learning: moving time and the largest gear cluster are read from the pairs") {
  const auto pairs = drive_in_gears({hatch_thetas()[1]}, 90.0, 1);
  const PairsSummary s = summarize_pairs(pairs);
  CHECK(s.moving_time == Approx(pairs.back().t - pairs.front().t).margin(1.0));
  CHECK(s.largest_cluster > 70);  // all but the clutch-out seconds and their neighbours
  std::vector<Sample> standing = pairs;
  for (Sample& p : standing)
    p.speed = 0.2;
  CHECK(summarize_pairs(standing).moving_time == 0.0);
  CHECK(summarize_pairs(standing).largest_cluster == 0);
}

TEST_CASE("learning: a fit on a minute in one gear gives that gear alone") {
  const double theta = hatch_thetas()[1];
  const auto pairs = drive_in_gears({theta}, 60.0, 2);
  REQUIRE(summarize_pairs(pairs).largest_cluster >= LearningSettings{}.cluster_pairs);
  const GearModel m = make_estimator_fitter()(pairs, {});
  INFO(m.reason);
  REQUIRE(m.gears.size() == 1);
  CHECK(m.gears[0].theta == Approx(theta).epsilon(0.01));
  // The offline fit asks for a ladder of two gears at least, as before.
  CHECK(fit_gear_model(pairs, {}).model.empty());
}

TEST_CASE("learning: a few minutes in 2nd and 3rd only fit 2 gears with their thetas") {
  const std::vector<double> seen = {hatch_thetas()[1], hatch_thetas()[2]};
  for (std::uint32_t seed = 1; seed <= 5; ++seed) {
    for (double minutes : {2.0, 3.0, 5.0}) {
      INFO("seed " << seed << ", " << minutes << " minutes");
      const GearModel m = make_estimator_fitter()(drive_in_gears(seen, 60.0 * minutes, seed), {});
      INFO(m.reason);
      REQUIRE(m.gears.size() == 2);
      CHECK(m.gears[0].theta == Approx(seen[0]).epsilon(0.01));
      CHECK(m.gears[1].theta == Approx(seen[1]).epsilon(0.01));
    }
  }
}

TEST_CASE("learning: a gear cruised at low revs while a cold engine idles high is a gear, not a slip") {
  // A first drive: 40 s standing with the engine idling 40 % high (cold), then 2nd gear through its revs
  // in turn with 4th held at one cruise (revs in a narrow band, 1.4 times that idle, at 8-9 m/s): the
  // cruise is no crawl, and the fit gives both gears.
  const double second = hatch_thetas()[1], fourth = hatch_thetas()[3];
  std::mt19937 rng(3);
  std::normal_distribution<double> speed_noise(0.0, 0.05), freq_noise(0.0, 0.2);
  constexpr double kColdIdle = 1.4 * 13.3;
  std::vector<Sample> pairs;
  double t = 0.0;
  for (; t < 40.0; t += 1.0)
    pairs.push_back({t, 0.0, kColdIdle + freq_noise(rng)});
  for (int turn = 0; turn < 4; ++turn) {
    for (double end = t + 30.0; t < end; t += 1.0) {
      const double f = 20.0 + 20.0 * 0.5 * (1.0 + std::sin(0.2 * t));
      pairs.push_back({t, second * f + speed_noise(rng), f + freq_noise(rng)});
    }
    for (double end = t + 45.0; t < end; t += 1.0) {
      const double f = 1.4 * kColdIdle * (1.0 + 0.015 * std::sin(0.1 * t));
      pairs.push_back({t, fourth * f + speed_noise(rng), f + freq_noise(rng)});
    }
  }
  REQUIRE(fourth * 1.4 * kColdIdle > 8.0);
  const GearModel m = make_estimator_fitter()(pairs, {});
  INFO(m.reason);
  REQUIRE(m.gears.size() == 2);
  CHECK(m.gears[0].theta == Approx(second).epsilon(0.01));
  CHECK(m.gears[1].theta == Approx(fourth).epsilon(0.01));
}

TEST_CASE("learning: a crawl on a slipping clutch at idle revs gives no gear") {
  // 2nd and 4th gear through their revs in turn with a crawl at 1.2-1.8 m/s, the engine held at 1.15 idles
  // on a slipping clutch: the crawl is no gear of the fit.
  const double second = hatch_thetas()[1], fourth = hatch_thetas()[3];
  std::mt19937 rng(4);
  std::normal_distribution<double> speed_noise(0.0, 0.05), freq_noise(0.0, 0.2);
  constexpr double kIdle = 13.3;
  std::vector<Sample> pairs;
  double t = 0.0;
  for (; t < 40.0; t += 1.0)
    pairs.push_back({t, 0.0, kIdle + freq_noise(rng)});
  for (int turn = 0; turn < 4; ++turn) {
    for (const double theta : {second, fourth}) {
      for (double end = t + 30.0; t < end; t += 1.0) {
        const double f = 20.0 + 20.0 * 0.5 * (1.0 + std::sin(0.2 * t));
        pairs.push_back({t, theta * f + speed_noise(rng), f + freq_noise(rng)});
      }
    }
    for (double end = t + 30.0; t < end; t += 1.0)
      pairs.push_back({t, 1.5 + 0.3 * std::sin(0.3 * t) + speed_noise(rng), 1.15 * kIdle + freq_noise(rng)});
  }
  const double crawl = 1.5 / (1.15 * kIdle);
  REQUIRE(std::abs(std::log(crawl / second)) > 0.3);
  const GearModel m = make_estimator_fitter()(pairs, {});
  INFO(m.reason);
  REQUIRE(m.gears.size() == 2);
  CHECK(m.gears[0].theta == Approx(second).epsilon(0.01));
  CHECK(m.gears[1].theta == Approx(fourth).epsilon(0.01));
}

TEST_CASE("learning: ten minutes of a CVT give no one-gear model") {
  // It holds one ratio at cruise, a line as sharp as a gear's; the continuum below it tells it apart.
  const sim::Vehicle cvt = sim::vehicle_preset("cvt");
  for (std::uint64_t seed = 1; seed <= 3; ++seed) {
    const auto observed = sim::simulate_observations(cvt, sim::DrivingStyle::kMixed, 600.0, 1, seed);
    const GearModel m = make_estimator_fitter()(sim::to_samples(observed), {});
    INFO("seed " << seed << ": " << m.gears.size() << " gears");
    CHECK(m.empty());
  }
}

TEST_CASE("learning: a one-gear model of a CVT is withdrawn once its continuum shows, a gearbox's is not") {
  const sim::Vehicle cvt = sim::vehicle_preset("cvt");
  GearModel top;
  top.gears = {{cvt.cvt_theta_max, 0.8, 0.001}};
  top.samples = 50;
  GearModel second;
  second.gears = {{hatch_thetas()[1], 0.8, 0.001}};
  second.samples = 50;
  for (std::uint64_t seed = 1; seed <= 3; ++seed) {
    INFO("seed " << seed);
    const auto pairs =
        sim::to_samples(sim::simulate_observations(cvt, sim::DrivingStyle::kMixed, 600.0, 1, seed));
    CHECK(one_gear_withdrawn(top, pairs));
    const auto manual = sim::to_samples(sim::simulate_observations(
        sim::vehicle_preset("hatch-5"), sim::DrivingStyle::kMixed, 600.0, 1, seed));
    CHECK_FALSE(one_gear_withdrawn(second, manual));
  }
  // Few pairs beside it are no ground either way; a model of two gears is never withdrawn.
  CHECK_FALSE(one_gear_withdrawn(second, drive_in_gears({hatch_thetas()[1]}, 120.0, 10)));
  GearModel two = second;
  two.gears.push_back({hatch_thetas()[2], 0.2, 0.001});
  CHECK_FALSE(one_gear_withdrawn(
      two, sim::to_samples(sim::simulate_observations(cvt, sim::DrivingStyle::kMixed, 600.0, 1, 1))));
}

TEST_CASE("learning: the retrainer withdraws a one-gear model a refit finds without ground") {
  TempDir dir;
  const sim::Vehicle cvt = sim::vehicle_preset("cvt");
  TrainingStore store(1e9, 100000);
  for (const Sample& s :
       sim::to_samples(sim::simulate_observations(cvt, sim::DrivingStyle::kMixed, 600.0, 1, 2)))
    store.add(s);
  ModelHolder model;
  GearModel top;
  top.gears = {{cvt.cvt_theta_max, 0.8, 0.001}};
  top.samples = 40;
  for (const bool installed : {false, true}) {
    INFO("model.json installed while the daemon ran: " << installed);
    model.set(std::make_shared<const GearModel>(top));
    write_text(dir / "model.json", serialize_model(top));
    model.set_file_stamp(stamp_of(dir / "model.json"));  // as loaded at start
    if (installed) {  // `gearpulse fit ... --out model.json` meanwhile: another file, not the daemon's
      std::filesystem::remove(dir / "model.json");
      write_text(dir / "model.json", serialize_model(top) + "\n");
    }
    Retrainer retrainer(store, model, dir / "model.json", make_estimator_fitter(), {});
    CHECK_FALSE(retrainer.retrain_now());
    INFO(retrainer.status().last_result);
    CHECK_FALSE(model.trained());
    CHECK(std::filesystem::exists(dir / "model.json") == installed);
    CHECK(retrainer.status().last_result.find("withdrawn") != std::string::npos);
  }
}

TEST_CASE("learning: a refit keeps a learned gear its pairs do not contradict") {
  const std::vector<double>& th = hatch_thetas();
  GearModel current;
  current.gears = {{th[1], 0.3, 0.0004}, {th[2], 0.4, 0.0005}, {th[3], 0.3, 0.0007}};
  current.samples = 600;
  current.extra["revs"] = nlohmann::json::array({{{"mean_log", 3.2}, {"sd_log", 0.2}, {"samples", 100}},
                                                 {{"mean_log", 3.3}, {"sd_log", 0.2}, {"samples", 200}},
                                                 {{"mean_log", 3.4}, {"sd_log", 0.2}, {"samples", 300}}});
  // The refit's pairs: 2nd and 3rd only (town), and a fit that found those two.
  const auto pairs = drive_in_gears({th[1], th[2]}, 240.0, 3);
  const GearModel fitted = make_estimator_fitter()(pairs, {});
  REQUIRE(fitted.gears.size() == 2);
  SECTION("not driven in the pairs: kept") {
    const GearModel merged = keep_seen_gears(current, fitted, pairs, 40);
    REQUIRE(merged.gears.size() == 3);
    CHECK(merged.gears[0].theta == fitted.gears[0].theta);
    CHECK(merged.gears[1].theta == fitted.gears[1].theta);
    CHECK(merged.gears[2].theta == th[3]);
    CHECK(merged.gears[2].std_error == 0.0007);
    double weights = 0.0, before = 0.0;
    for (const Gear& g : merged.gears)
      weights += g.weight;
    for (const Gear& g : fitted.gears)
      before += g.weight;
    CHECK(weights == Approx(before));
    REQUIRE(merged.extra["revs"].size() == 3);
    CHECK(merged.extra["revs"][2]["samples"] == 300);
    CHECK(merged.extra[kKeptGears] == nlohmann::json::array({th[3]}));
  }
  SECTION("driven through without a line there: contradicted, dropped") {
    // Pairs smeared evenly over +-10 % around the old line: a continuum, as a CVT or a slipping clutch.
    std::vector<Sample> smeared = pairs;
    double t = pairs.back().t + 1.0;
    for (int k = 0; k < 120; ++k, t += 1.0) {
      const double f = 30.0;
      smeared.push_back({t, th[3] * f * (0.9 + 0.2 * k / 120.0), f});
    }
    const GearModel merged = keep_seen_gears(current, fitted, smeared, 40);
    CHECK(merged.gears.size() == 2);
    CHECK(merged.extra.find(kKeptGears) == merged.extra.end());
  }
  SECTION("the fit's gears below its ladder stay only below the merged ladder") {
    GearModel launch = current;  // first, third and fourth gear learned
    launch.gears[0].theta = th[0];
    GearModel refit = fitted;  // the refit recorded first gear below its ladder, and one lower still
    refit.extra["lower_gears"] = nlohmann::json::array({0.6 * th[0], 1.01 * th[0]});
    const GearModel merged = keep_seen_gears(launch, refit, pairs, 40);
    REQUIRE(merged.gears.size() == 4);
    CHECK(merged.gears[0].theta == th[0]);
    CHECK(merged.extra["lower_gears"] == nlohmann::json::array({0.6 * th[0]}));
  }
  SECTION("a gear the refit moved is the refit's") {
    GearModel moved = current;
    moved.gears[0].theta = fitted.gears[0].theta * 1.03;
    moved.gears.erase(moved.gears.begin() + 2);
    moved.extra["revs"].erase(2);
    const GearModel merged = keep_seen_gears(moved, fitted, pairs, 40);
    REQUIRE(merged.gears.size() == 2);
    CHECK(merged.gears[0].theta == fitted.gears[0].theta);
  }
}

TEST_CASE("learning: the gear count grows as gears are seen and does not shrink on a drive in town") {
  const std::vector<double>& th = hatch_thetas();
  // 2nd and 3rd, then 4th as well, then town again (2nd and 3rd): 2, 3, then still 3 gears.
  std::vector<Sample> pairs = drive_in_gears({th[1], th[2]}, 180.0, 4);
  const auto fitter = make_estimator_fitter();
  GearModel model = fitter(pairs, {});
  REQUIRE(model.gears.size() == 2);
  const auto more = drive_in_gears({th[1], th[2], th[3]}, 240.0, 5, pairs.back().t + 1.0);
  pairs.insert(pairs.end(), more.begin(), more.end());
  model = keep_seen_gears(model, fitter(pairs, {}), pairs, 40);
  REQUIRE(model.gears.size() == 3);
  // A store that has let the 4th-gear pairs go (its hours are up): the fit finds two, the model keeps three.
  const auto town = drive_in_gears({th[1], th[2]}, 300.0, 6, pairs.back().t + 1.0);
  const GearModel refit = fitter(town, {});
  REQUIRE(refit.gears.size() == 2);
  model = keep_seen_gears(model, refit, town, 40);
  REQUIRE(model.gears.size() == 3);
  CHECK(model.gears[2].theta == Approx(th[3]).epsilon(0.01));
}

TEST_CASE("learning: the retrainer's first fit comes as soon as the pairs show one gear, status says young") {
  TempDir dir;
  TrainingStore store(1e9, 100000);
  for (const Sample& s : drive_in_gears({hatch_thetas()[1]}, 60.0, 7, 1.7e9))
    store.add(s);
  ModelHolder model;
  Retrainer::Settings settings;  // min_new_samples 600: the interval rule alone would not fit yet
  Retrainer retrainer(store, model, dir / "model.json", make_estimator_fitter(), settings);
  CHECK(retrainer.status().young);
  retrainer.start();
  // A minute at most: the fit runs at SCHED_IDLE, which a loaded machine serves last, and a sanitized
  // build is several times slower. The bound is for a failing test only.
  for (int i = 0; i < 6000 && !model.trained(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  retrainer.stop();
  REQUIRE(model.trained());
  CHECK(model.get()->gears.size() == 1);
  const Retrainer::Status s = retrainer.status();
  CHECK(s.young);
  CHECK(s.moving_time == Approx(59.0).margin(3.0));
  CHECK(s.cluster_pairs >= 40);
  REQUIRE(LearningSchedule().next_refit(s.moving_time).has_value());
  CHECK(s.next_refit == Approx(*LearningSchedule().next_refit(s.moving_time)));
}

// docs/cold-start.md: a reset-model that clears the training pairs starts the schedule again. A retrainer
// that remembered the fit before the reset waited for a refit time, or a cluster larger than the old one,
// past what the new pairs showed: minutes of driving with no model.
TEST_CASE("learning: after a reset the schedule starts again, with the pairs cleared or kept") {
  for (const bool cleared : {true, false}) {
    INFO("pairs cleared: " << cleared);
    TempDir dir;
    TrainingStore store(1e9, 100000);
    for (const Sample& s : drive_in_gears({hatch_thetas()[1]}, 200.0, 7, 1.7e9))
      store.add(s);
    ModelHolder model;
    std::atomic<int> fits{0};
    const auto fitter = make_estimator_fitter();
    Retrainer retrainer(
        store, model, dir / "model.json",
        [&](std::span<const Sample> pairs, std::stop_token stop) {
          ++fits;
          return fitter(pairs, std::move(stop));
        },
        Retrainer::Settings{});  // min_new_samples 600: only the schedule fits here
    retrainer.start();
    const auto wait_trained = [&] {
      // The bound is for a failing test only (a fit at SCHED_IDLE on a loaded, sanitized run).
      for (int i = 0; i < 6000 && !model.trained(); ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      return model.trained();
    };
    REQUIRE(wait_trained());
    const int before = fits.load();
    {  // what StateDirectory::reset_model does in memory
      const auto lock = model.lock_writes();
      model.set(nullptr);
    }
    if (cleared) {
      store.clear();
      for (const Sample& s : drive_in_gears({hatch_thetas()[1]}, 200.0, 8, 1.8e9))
        store.add(s);
    }
    retrainer.model_reset(cleared);
    CHECK(wait_trained());
    CHECK(fits.load() > before);
    retrainer.stop();
  }
}
