// Accuracy of the estimator on simulated drives: vehicles x driving styles (40 min at 1 Hz) in auto mode
// and in the paper's mode, the same on vehicles drawn at random (sim::random_vehicle: nothing tuned to the
// presets), then a Monte-Carlo run comparing the spread of theta with the Cramer-Rao bound.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "bench/requirements.hpp"
#include "core/estimator.hpp"
#include "core/mixture_likelihood.hpp"
#include "tools/sim/vehicle_sim.hpp"

using namespace gearpulse;

namespace {

const sim::DrivingStyle kStyles[] = {sim::DrivingStyle::kMixed, sim::DrivingStyle::kUrban,
                                     sim::DrivingStyle::kHighway, sim::DrivingStyle::kTrafficJam};

struct Score {
  std::size_t found = 0;
  double max_error = 0.0;  // %, when the count is right
  int worst = -1;          // gear index of max_error
  double max_z = 0.0;      // largest |error| / standard error, when the count is right
  bool ok = false;
};

Score score(const sim::Vehicle& car, const GearModel& model) {
  Score s;
  s.found = model.gears.size();
  if (s.found != car.theta.size()) return s;
  for (std::size_t i = 0; i < s.found; ++i) {
    const double error = 100.0 * std::abs(model.gears[i].theta / car.theta[i] - 1.0);
    if (error > s.max_error) {
      s.max_error = error;
      s.worst = static_cast<int>(i);
    }
    if (model.gears[i].std_error > 0.0)
      s.max_z = std::max(s.max_z, std::abs(model.gears[i].theta - car.theta[i]) / model.gears[i].std_error);
  }
  s.ok = s.max_error <= 0.5;
  return s;
}

// Samples with each gear engaged (index 0 = first gear).
// Runs with the right gear count, and of those the ones with every theta within 0.5, 1 and 2 %.
struct Tally {
  int right = 0;
  int within[3] = {0, 0, 0};
  void add(const sim::Vehicle& car, const Score& a) {
    if (a.found != car.theta.size()) return;
    ++right;
    within[0] += a.max_error <= 0.5 ? 1 : 0;
    within[1] += a.max_error <= 1.0 ? 1 : 0;
    within[2] += a.max_error <= 2.0 ? 1 : 0;
  }
};

std::vector<int> engaged_counts(const sim::Vehicle& car, const std::vector<sim::Observation>& observed) {
  std::vector<int> n(static_cast<std::size_t>(car.gears()), 0);
  for (const sim::Observation& o : observed) {
    if (o.truth.clutch == sim::Clutch::kEngaged && o.truth.gear >= 1)
      ++n[static_cast<std::size_t>(o.truth.gear - 1)];
  }
  return n;
}

// The paper's priors for a vehicle: Table 2 for the 5-speed BMW, else its true steps rounded to 0.05
// (what a gearbox data sheet gives), top gear down.
std::vector<double> paper_ratios(const sim::Vehicle& car) {
  if (car.name == "bmw-520i") return {1.25, 1.35, 1.50, 1.7};
  std::vector<double> c;
  for (std::size_t i = car.theta.size() - 1; i > 0; --i)
    c.push_back(std::round(car.theta[i] / car.theta[i - 1] * 20.0) / 20.0);
  return c;
}

// Why a run missed: the gear at fault and how often the drive engaged it, or, with a wrong count, how often
// each gear was engaged (a gear seen a dozen times cannot be pinned to 0.5 %: its standard error is about
// that). Counts the miss in used_rarely when that gear, or the least used one, was engaged fewer than 40
// times.
std::string explain_miss(const std::string& run, const sim::Vehicle& car, const Score& a,
                         const std::vector<int>& engaged, int& used_rarely) {
  char why[200];
  if (a.found == car.theta.size()) {
    const int seen = engaged[static_cast<std::size_t>(a.worst)];
    used_rarely += seen < 40 ? 1 : 0;
    std::snprintf(why, sizeof why, "  %s: gear %d (engaged %d times) off %.2f %% = %.1f stderr\n",
                  run.c_str(), a.worst + 1, seen, a.max_error, a.max_z);
    return why;
  }
  used_rarely += *std::min_element(engaged.begin(), engaged.end()) < 40 ? 1 : 0;
  std::string counts;
  for (int c : engaged) {
    if (!counts.empty()) counts += ',';
    counts += std::to_string(c);
  }
  std::snprintf(why, sizeof why, "  %s: %zu gears found; gears engaged [%s] times\n", run.c_str(), a.found,
                counts.c_str());
  return why;
}

void accuracy_table(int first_seed, int seeds, bench::Requirements& required) {
  const int last_seed = first_seed + seeds - 1;
  std::printf("\n== accuracy: 40 min at 1 Hz, sigma_v 0.05 m/s, sigma_s 0.2 Hz, seeds %d..%d\n", first_seed,
              last_seed);
  std::printf("%-10s %-8s %5s | %-28s | %-28s\n", "vehicle", "style", "gears", "auto: found / max err % (ok)",
              "paper: max err % (ok)");
  int auto_ok = 0;
  int paper_ok = 0;
  int total = 0;
  int cvt_clean = 0;
  int cvt_total = 0;
  int right_count = 0;
  int within_3se = 0;
  int used_rarely = 0;
  std::string misses;
  for (const sim::Vehicle& car : sim::vehicle_presets()) {
    for (sim::DrivingStyle style : kStyles) {
      std::string auto_cell;
      std::string paper_cell;
      for (int seed = first_seed; seed <= last_seed; ++seed) {
        const auto observed =
            sim::simulate_observations(car, style, 2400.0, 1, static_cast<std::uint64_t>(seed));
        const auto samples = sim::to_samples(observed);
        const FitResult fit = fit_gear_model(samples, {});
        char cell[64];
        if (car.is_cvt()) {
          ++cvt_total;
          cvt_clean += fit.model.gears.empty() ? 1 : 0;
          std::snprintf(cell, sizeof cell, "%zu ", fit.model.gears.size());
          auto_cell += cell;
          continue;
        }
        const Score a = score(car, fit.model);
        ++total;
        auto_ok += a.ok ? 1 : 0;
        if (a.found == car.theta.size()) {
          ++right_count;
          within_3se += a.max_z <= 3.0 ? 1 : 0;
        }
        if (!a.ok) {
          const std::string run =
              car.name + " " + std::string(sim::style_name(style)) + " seed " + std::to_string(seed);
          misses += explain_miss(run, car, a, engaged_counts(car, observed), used_rarely);
        }
        std::snprintf(cell, sizeof cell, "%zu/%.2f%s ", a.found, a.max_error, a.ok ? "" : "*");
        auto_cell += cell;
        FitOptions paper;
        paper.ratios = paper_ratios(car);
        const Score p = score(car, fit_gear_model(samples, paper).model);
        paper_ok += p.ok ? 1 : 0;
        std::snprintf(cell, sizeof cell, "%.2f%s ", p.max_error, p.ok ? "" : "*");
        paper_cell += cell;
      }
      std::printf("%-10s %-8s %5d | %-28s | %-28s\n", car.name.c_str(),
                  std::string(sim::style_name(style)).c_str(), car.gears(), auto_cell.c_str(),
                  paper_cell.c_str());
    }
  }
  std::printf("auto mode: right count and every theta within 0.5 %%: %d / %d runs\n", auto_ok, total);
  std::printf("auto misses:\n%s", misses.c_str());
  std::printf("auto misses on a gear engaged fewer than 40 times in the drive: %d / %d\n", used_rarely,
              total - auto_ok);
  std::printf("auto, right count: every theta within 3 of its standard errors: %d / %d runs\n", within_3se,
              right_count);
  std::printf(
      "paper mode (true count and data-sheet priors given): every theta within 0.5 %%: %d / %d runs\n",
      paper_ok, total);
  std::printf("CVT: no ladder in %d / %d runs\n", cvt_clean, cvt_total);
  std::printf("(* = wrong count or an error above 0.5 %%)\n");
  required.report("auto_ok_pct", 100.0 * auto_ok / std::max(total, 1));
  required.report("auto_right_count_pct", 100.0 * right_count / std::max(total, 1));
  required.report("paper_ok_pct", 100.0 * paper_ok / std::max(total, 1));
  required.report("cvt_no_ladder_pct", 100.0 * cvt_clean / std::max(cvt_total, 1));
}

// Auto mode on vehicles drawn at random, one 40-minute drive at 1 Hz each, the styles in turn.
// Vehicle k (from first_vehicle on) is driven with seed 1 + k - 5000.
// With wide, the vehicles are sim::wide_vehicle's (3-9 gears, diesels, motorcycles, irregular ladders).
void random_vehicles(int first_vehicle, int count, bool wide, bench::Requirements& required) {
  std::printf("\n== random vehicles (sim::%s %d..%d), 40 min at 1 Hz, styles in turn\n",
              wide ? "wide_vehicle" : "random_vehicle", first_vehicle, first_vehicle + count - 1);
  int ok = 0;
  int right_count = 0;
  int used_rarely = 0;
  std::string misses;
  for (int r = 0; r < count; ++r) {
    const int k = first_vehicle + r;
    const sim::Vehicle car = wide ? sim::wide_vehicle(static_cast<std::uint64_t>(k))
                                  : sim::random_vehicle(static_cast<std::uint64_t>(k));
    const sim::DrivingStyle style = kStyles[r % 4];
    const auto observed =
        sim::simulate_observations(car, style, 2400.0, 1, static_cast<std::uint64_t>(1 + k - 5000));
    const Score a = score(car, fit_gear_model(sim::to_samples(observed), {}).model);
    ok += a.ok ? 1 : 0;
    right_count += a.found == car.theta.size() ? 1 : 0;
    if (a.ok) continue;
    const std::string run =
        car.name + " (" + std::to_string(car.gears()) + " gears) " + std::string(sim::style_name(style));
    misses += explain_miss(run, car, a, engaged_counts(car, observed), used_rarely);
  }
  std::printf("misses:\n%s", misses.c_str());
  std::printf("random vehicles: right count %d / %d; right count and every theta within 0.5 %%: %d / %d\n",
              right_count, count, ok, count);
  std::printf("misses on a gear engaged fewer than 40 times in the drive: %d / %d\n", used_rarely,
              count - ok);
  required.report("random_right_count_pct", 100.0 * right_count / std::max(count, 1));
  required.report("random_ok_pct", 100.0 * ok / std::max(count, 1));
}

// Auto mode on the presets under other logging conditions than the paper's (1 Hz, a u-blox class
// receiver, a clean tracker): rows every 2 s, a coarse GPS, a noisy tracker, an OBD logger (integer km/h
// and rpm, skewed polls every 1.8 s). Right count, and how close the thetas are when it is right.
void logging_conditions(int seeds) {
  struct Condition {
    const char* name;
    sim::ObservationOptions options;
  };
  std::vector<Condition> conditions(5);
  conditions[0].name = "1 Hz (as above)";
  conditions[1].name = "rows every 2 s";
  conditions[1].options.period = 2.0;
  conditions[2].name = "GPS sigma 0.3 m/s";
  conditions[2].options.sigma_speed = 0.3;
  conditions[3].name = "tracker sigma 1 Hz";
  conditions[3].options.sigma_freq = 1.0;
  conditions[4].name = "OBD 1.8 s polls";
  conditions[4].options.obd = true;
  conditions[4].options.period = 0.5;
  std::printf("\n== logging conditions: 7 manual presets x 4 styles, 40 min, seeds 1..%d (%d runs each)\n",
              seeds, 28 * seeds);
  // The CVT over more seeds: a ladder on it is rare, and a few seeds would not show one.
  constexpr int kCvtSeeds = 20;
  std::printf("%-20s %12s %10s %10s %10s   %s\n", "condition", "right count", "<= 0.5 %", "<= 1 %", "<= 2 %",
              "CVT: ladders in 4 styles x seeds 1..20");
  for (const Condition& c : conditions) {
    Tally tally;
    int cvt_ladders = 0;
    for (const sim::Vehicle& car : sim::vehicle_presets()) {
      for (sim::DrivingStyle style : kStyles) {
        for (int seed = 1; seed <= (car.is_cvt() ? kCvtSeeds : seeds); ++seed) {
          const auto observed = sim::simulate_observations(car, style, 2400.0, 1, seed, c.options);
          const GearModel model = fit_gear_model(sim::to_samples(observed), {}).model;
          if (car.is_cvt()) {
            cvt_ladders += model.gears.empty() ? 0 : 1;
            continue;
          }
          tally.add(car, score(car, model));
        }
      }
    }
    std::printf("%-20s %12d %10d %10d %10d   %d / %d\n", c.name, tally.right, tally.within[0],
                tally.within[1], tally.within[2], cvt_ladders, 4 * kCvtSeeds);
  }
}

// A speed channel that lags engine speed (a GPS fix reported after the audio it belongs to, an ECU's
// late speed): each row's speed is the one observed lag seconds earlier. The fit searches the lag
// (extra.speed_lag) and moves the speeds by it; the table shows the lag found and how close the thetas
// come, drive by drive, on urban drives (the most launches, where a lag costs most).
void speed_lag_table(int seeds) {
  struct Rate {
    const char* name;
    std::size_t every;  // rows of the 10 Hz observation kept
    double sigma_speed;
  };
  // Observed at 50 Hz, rows kept at 1 or 10 Hz; the lags are not whole samples at either rate.
  constexpr double kFine = 0.02;
  const Rate rates[] = {{"1 Hz", 50, 0.05}, {"1 Hz, sigma 0.3", 50, 0.3}, {"10 Hz", 5, 0.05}};
  std::printf("\n== speed lag: 7 manual presets, urban, 40 min, seeds 1..%d (%d runs per cell)\n", seeds,
              7 * seeds);
  std::printf("%-16s %6s | %22s | %12s %10s %10s %10s\n", "observed", "lag s", "found: median / worst",
              "right count", "<= 0.5 %", "<= 1 %", "<= 2 %");
  for (const Rate& rate : rates) {
    for (double lag : {0.0, 0.32, 0.74, 1.46}) {
      std::vector<double> off;
      Tally tally;
      for (const sim::Vehicle& car : sim::vehicle_presets()) {
        if (car.is_cvt()) continue;
        for (int seed = 1; seed <= seeds; ++seed) {
          sim::ObservationOptions fine;
          fine.period = kFine;
          fine.sigma_speed = rate.sigma_speed;
          const auto observed = sim::simulate_observations(car, sim::DrivingStyle::kUrban, 2400.0, 1,
                                                           static_cast<std::uint64_t>(seed), fine);
          const auto lag_rows = static_cast<std::size_t>(std::lround(lag / kFine));
          std::vector<Sample> samples;
          for (std::size_t k = lag_rows; k < observed.size(); k += rate.every)
            samples.push_back({observed[k].truth.t, observed[k - lag_rows].speed, observed[k].freq});
          const GearModel model = fit_gear_model(samples, {}).model;
          off.push_back(model.extra.value("speed_lag", 0.0) - lag);
          tally.add(car, score(car, model));
        }
      }
      std::vector<double> size(off.size());
      std::transform(off.begin(), off.end(), size.begin(), [](double x) { return std::abs(x); });
      std::sort(size.begin(), size.end());
      const double worst = *std::max_element(off.begin(), off.end(),
                                             [](double x, double y) { return std::abs(x) < std::abs(y); });
      std::printf("%-16s %6.2f | %+10.3f / %+9.3f | %12d %10d %10d %10d\n", rate.name, lag,
                  size[size.size() / 2], worst, tally.right, tally.within[0], tally.within[1],
                  tally.within[2]);
    }
  }
}

detail::MixtureData mixture_data(const std::vector<Sample>& samples) {
  detail::MixtureData data;
  for (const Sample& x : samples) {
    if (!x.has_speed() || !x.has_freq() || x.speed < 0.0 || x.freq <= 0.0) continue;  // as the estimator
    data.v.push_back(x.speed);
    data.s.push_back(x.freq);
  }
  return data;
}

// Fisher information about (theta, sigma_s, sigma_v, weights) carried by a data set at the truth: thetas
// and sigmas at their true values, the nuisance weights and clutch-out density fitted with them held
// (started from a fitted model's). Sum of score outer products (equals minus the expected Hessian when
// the model holds).
Eigen::MatrixXd fisher_at_truth(const sim::Vehicle& car, const detail::MixtureData& data,
                                const sim::ObservationOptions& obs, const GearModel& start) {
  detail::MixtureParams p;
  p.theta = car.theta;
  for (const Gear& g : start.gears)
    p.alpha.push_back(g.weight);
  p.sigma_s = obs.sigma_freq;
  p.sigma_v = obs.sigma_speed;
  p.beta_stand = start.extra["standstill"]["weight"].get<double>();
  p.stand_sigma = start.extra["standstill"]["sigma"].get<double>();
  p.beta_clutch = start.extra["clutch_out"]["weight"].get<double>();
  p.g_lo = start.extra["clutch_out"]["lo"].get<double>();
  p.g_hi = start.extra["clutch_out"]["hi"].get<double>();
  p.g_density = start.extra["clutch_out"]["density"].get<std::vector<double>>();
  for (int it = 0; it < 30; ++it) {
    const detail::EStepStats st = detail::e_step(data, p);
    detail::m_step(st, p, false, false);
    p.theta = car.theta;  // held at the truth
    p.sigma_s = obs.sigma_freq;
    p.sigma_v = obs.sigma_speed;
  }
  const detail::GradientLayout layout{car.gears(), true, true};
  Eigen::MatrixXd info = Eigen::MatrixXd::Zero(layout.size(), layout.size());
  detail::MixtureData one;
  one.v.resize(1);
  one.s.resize(1);
  Eigen::VectorXd g;
  for (std::size_t k = 0; k < data.size(); ++k) {
    one.v[0] = data.v[k];
    one.s[0] = data.s[k];
    (void)detail::log_likelihood_gradient(one, p, layout, g);
    info += g * g.transpose();
  }
  return info;
}

// The spread of theta over drives against two Cramer-Rao bounds. "per drive": the mean over the runs of
// the bound for that drive's own samples (how much each gear was used varies from drive to drive, and
// the variance of an efficient estimator is the mean of 1/information, not 1/mean information). "pooled":
// the bound for the mean information per sample of a long drive times the mean sample count, which is
// optimistic for gears whose use varies much (5th gear in town).
void monte_carlo(int runs) {
  const sim::Vehicle car = sim::vehicle_preset("hatch-5");
  const sim::DrivingStyle style = sim::DrivingStyle::kUrban;
  const sim::ObservationOptions obs;
  std::printf("\n== Monte-Carlo: %s, %s, 40 min at 1 Hz, %d seeds (1000..%d)\n", car.name.c_str(),
              std::string(sim::style_name(style)).c_str(), runs, 1000 + runs - 1);
  const int m = car.gears();
  std::vector<std::vector<double>> theta(static_cast<std::size_t>(m));
  std::vector<double> se(static_cast<std::size_t>(m), 0.0);
  std::vector<double> crb_var(static_cast<std::size_t>(m), 0.0);
  GearModel reference;
  double samples = 0.0;
  int complete = 0;
  for (int r = 0; r < runs; ++r) {
    const auto data = sim::to_samples(sim::simulate_observations(car, style, 2400.0, 1, 1000 + r, obs));
    const FitResult fit = fit_gear_model(data, {});
    if (static_cast<int>(fit.model.gears.size()) != m) continue;
    ++complete;
    samples += static_cast<double>(fit.model.samples);
    const Eigen::MatrixXd bound = fisher_at_truth(car, mixture_data(data), obs, fit.model).inverse();
    for (int i = 0; i < m; ++i) {
      theta[static_cast<std::size_t>(i)].push_back(fit.model.gears[static_cast<std::size_t>(i)].theta);
      se[static_cast<std::size_t>(i)] += fit.model.gears[static_cast<std::size_t>(i)].std_error;
      crb_var[static_cast<std::size_t>(i)] += bound(i, i);
    }
    if (reference.gears.empty()) reference = fit.model;
  }
  std::printf("runs with the right gear count: %d / %d\n", complete, runs);
  if (complete < 3) return;
  samples /= complete;
  const detail::MixtureData long_drive =
      mixture_data(sim::to_samples(sim::simulate_observations(car, style, 2400.0, 40, 7000, obs)));
  const Eigen::MatrixXd pooled =
      (samples / static_cast<double>(long_drive.size()) * fisher_at_truth(car, long_drive, obs, reference))
          .inverse();
  std::printf("%-5s %9s %10s %10s %10s %10s %8s %8s %10s %8s\n", "gear", "theta", "bias/sem", "std (MC)",
              "stderr", "CRB drive", "std/CRB", "se/CRB", "CRB pooled", "std/CRBp");
  for (int i = 0; i < m; ++i) {
    const auto& t = theta[static_cast<std::size_t>(i)];
    const double truth = car.theta[static_cast<std::size_t>(i)];
    double mean = 0.0;
    for (double x : t)
      mean += x / complete;
    double var = 0.0;
    for (double x : t)
      var += (x - mean) * (x - mean) / (complete - 1);
    const double sd = std::sqrt(var);
    const double bound = std::sqrt(crb_var[static_cast<std::size_t>(i)] / complete);
    const double bound_pooled = std::sqrt(pooled(i, i));
    const double mean_se = se[static_cast<std::size_t>(i)] / complete;
    std::printf("%-5d %9.5f %10.2f %10.3e %10.3e %10.3e %8.2f %8.2f %10.3e %8.2f\n", i + 1, truth,
                (mean - truth) / (sd / std::sqrt(complete)), sd, mean_se, bound, sd / bound, mean_se / bound,
                bound_pooled, sd / bound_pooled);
  }
  std::printf("(a std/CRB ratio from n runs is itself uncertain by about 1/sqrt(2n): +-%.0f %% here)\n",
              100.0 / std::sqrt(2.0 * complete));
}

}  // namespace

int main(int argc, char** argv) {
  // Options before the positional arguments: --first-seed N (the accuracy table's seeds start at N, 1
  // by default), --first-vehicle K (the random vehicles start at K, 5000 by default), --wide (the random
  // vehicles drawn by sim::wide_vehicle instead of sim::random_vehicle), --require (above).
  bench::Requirements required;
  if (!required.parse(argc, argv)) return 2;
  int first_seed = 1;
  int first_vehicle = 5000;
  bool wide = false;
  int shift = 0;
  while (1 + shift < argc) {
    const std::string a = argv[1 + shift];
    if (a == "--wide") {
      wide = true;
      shift += 1;
    } else if (a == "--first-seed" && 2 + shift < argc) {
      first_seed = std::atoi(argv[2 + shift]);
      shift += 2;
    } else if (a == "--first-vehicle" && 2 + shift < argc) {
      first_vehicle = std::atoi(argv[2 + shift]);
      shift += 2;
    } else {
      break;
    }
  }
  argc -= shift;
  argv += shift;
  const int seeds = argc > 1 ? std::atoi(argv[1]) : 2;
  const int runs = argc > 2 ? std::atoi(argv[2]) : 50;
  const int random = argc > 3 ? std::atoi(argv[3]) : 40;
  const int conditions = argc > 4 ? std::atoi(argv[4]) : 2;
  std::printf(
      "bench_fit_sim [seeds per cell = %d] [Monte-Carlo runs = %d] [random vehicles = %d] [seeds per logging "
      "condition = %d]\n",
      seeds, runs, random, conditions);
  if (seeds > 0) accuracy_table(first_seed, seeds, required);
  if (random > 0) random_vehicles(first_vehicle, random, wide, required);
  if (conditions > 0) logging_conditions(conditions);
  if (conditions > 0) speed_lag_table(conditions);
  if (runs > 0) monte_carlo(runs);
  return required.exit_status();
}
