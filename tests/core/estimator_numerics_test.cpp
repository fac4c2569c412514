// The estimator's numerics: standard errors against the spread over seeds, the analytic observed
// information against the numeric one, and the passes over a large log split into slices (two threads,
// or the caller's runner) giving the sums of their parts.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <functional>
#include <random>
#include <vector>

#include <Eigen/Dense>

#include "core/estimator.hpp"
#include "core/mixture_likelihood.hpp"
#include "core/slice_runner.hpp"
#include "tests/core/estimator_drives.hpp"
#include "tools/sim/vehicle_sim.hpp"

using namespace gearpulse;
using gearpulse::test::simulate;

TEST_CASE("estimator: standard errors match the spread over seeds") {
  const sim::Vehicle car = sim::vehicle_preset("hatch-5");
  const int runs = 12;
  std::vector<std::vector<double>> theta(5);
  std::vector<double> mean_se(5, 0.0);
  int complete = 0;
  for (int r = 0; r < runs; ++r) {
    const FitResult fit = fit_gear_model(simulate(car, sim::DrivingStyle::kUrban, 2400.0, 1, 100 + r), {});
    if (fit.model.gears.size() != 5) continue;  // a missed first gear: counted by the bench, not here
    ++complete;
    for (std::size_t i = 0; i < 5; ++i) {
      theta[i].push_back(fit.model.gears[i].theta);
      mean_se[i] += fit.model.gears[i].std_error;
    }
  }
  REQUIRE(complete >= runs * 3 / 4);
  for (double& se : mean_se)
    se /= complete;
  for (std::size_t i = 2; i < 5; ++i) {  // the well-populated gears: enough samples for a spread
    double mean = 0.0;
    for (double t : theta[i])
      mean += t / complete;
    double var = 0.0;
    for (double t : theta[i])
      var += (t - mean) * (t - mean) / (complete - 1);
    const double ratio = std::sqrt(var) / mean_se[i];
    INFO("gear " << i + 1 << " spread/stderr " << ratio);
    CHECK(ratio > 0.4);
    CHECK(ratio < 2.5);
  }
}

namespace {
// A mixture for the BMW's five gears with a standstill spike and eight bins of clutch-out density.
detail::MixtureParams bmw_mixture(const sim::Vehicle& car) {
  detail::MixtureParams p;
  p.theta = car.theta;
  p.alpha = {0.03, 0.1, 0.2, 0.2, 0.1};
  p.beta_stand = 0.2;
  p.stand_sigma = 0.05;
  p.beta_clutch = 0.17;
  p.g_lo = 0.0;
  p.g_hi = 40.0;
  p.g_density.assign(8, 1.0 / 40.0);
  p.sigma_s = 0.25;
  p.sigma_v = 0.06;
  return p;
}
}  // namespace

TEST_CASE("estimator: analytic observed information equals the numeric one") {
  const sim::Vehicle car = sim::bmw_520i();
  const auto obs = sim::simulate_observations(car, sim::DrivingStyle::kUrban, 1200.0, 1, 9);
  detail::MixtureData data;
  for (const auto& o : obs) {
    data.v.push_back(o.speed);
    data.s.push_back(o.freq);
  }
  const detail::MixtureParams p = bmw_mixture(car);
  const detail::GradientLayout layout{5, true, true};
  const Eigen::MatrixXd a = detail::observed_information(data, p, layout);
  const Eigen::MatrixXd n = detail::observed_information_numeric(data, p, layout);
  for (int i = 0; i < a.rows(); ++i) {
    for (int j = 0; j < a.cols(); ++j) {
      const double scale = std::sqrt(std::abs(n(i, i) * n(j, j))) + 1e-9;
      CHECK(std::abs(a(i, j) - n(i, j)) / scale < 1e-4);
    }
  }
}

TEST_CASE("estimator: a log long enough for two threads gives the sums of its parts") {
  // Every pass over the data (log-likelihood, gradient, observed information, E-step) splits a log of
  // kParallelSamples or more between two threads; each part here is short enough for one.
  const std::size_t n = detail::kParallelSamples + 2001;
  const std::size_t cut = 15000;
  REQUIRE(cut < detail::kParallelSamples);
  REQUIRE(n - cut < detail::kParallelSamples);
  const sim::Vehicle car = sim::bmw_520i();
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, 1.0);
  detail::MixtureData all, head, tail;
  for (std::size_t k = 0; k < n; ++k) {
    const double u = unit(rng);
    double s = 12.0 + 80.0 * unit(rng), v = 0.0;
    if (u < 0.15) {
      s = 13.0 + 0.3 * noise(rng);  // standing at idle
      v = std::abs(0.03 * noise(rng));
    } else if (u < 0.25) {
      v = 30.0 * unit(rng);  // declutched
    } else {
      const auto gear = static_cast<std::size_t>(unit(rng) * static_cast<double>(car.theta.size()));
      v = car.theta[std::min(gear, car.theta.size() - 1)] * (s + 0.3 * noise(rng)) + 0.05 * noise(rng);
    }
    for (detail::MixtureData* d : {&all, k < cut ? &head : &tail}) {
      d->v.push_back(v);
      d->s.push_back(s);
    }
  }
  const detail::MixtureParams p = bmw_mixture(car);
  const auto same = [](double whole, double parts) {
    return std::abs(whole - parts) <= 1e-9 * (std::abs(whole) + std::abs(parts)) + 1e-12;
  };

  CHECK(same(detail::log_likelihood(all, p),
             detail::log_likelihood(head, p) + detail::log_likelihood(tail, p)));

  const detail::GradientLayout layout{5, true, true};
  Eigen::VectorXd g_all, g_head, g_tail;
  const double ll_all = detail::log_likelihood_gradient(all, p, layout, g_all);
  const double ll_parts = detail::log_likelihood_gradient(head, p, layout, g_head) +
                          detail::log_likelihood_gradient(tail, p, layout, g_tail);
  CHECK(same(ll_all, ll_parts));
  REQUIRE(g_all.size() == layout.size());
  for (int i = 0; i < layout.size(); ++i) {
    INFO("gradient " << i);
    CHECK(same(g_all[i], g_head[i] + g_tail[i]));
  }

  const Eigen::MatrixXd info_all = detail::observed_information(all, p, layout);
  const Eigen::MatrixXd info_parts =
      detail::observed_information(head, p, layout) + detail::observed_information(tail, p, layout);
  for (int i = 0; i < layout.size(); ++i) {
    for (int j = 0; j < layout.size(); ++j) {
      // Off the diagonal many entries cancel to zero: they are compared on the scale of the diagonal.
      INFO("information " << i << ", " << j << ": " << info_all(i, j) << " against " << info_parts(i, j));
      const double scale = std::sqrt(std::abs(info_all(i, i) * info_all(j, j)));
      CHECK(std::abs(info_all(i, j) - info_parts(i, j)) <= 1e-9 * scale);
    }
  }

  const detail::EStepStats e_all = detail::e_step(all, p);
  const detail::EStepStats e_head = detail::e_step(head, p);
  const detail::EStepStats e_tail = detail::e_step(tail, p);
  CHECK(same(e_all.log_likelihood, e_head.log_likelihood + e_tail.log_likelihood));
  REQUIRE(e_all.r.size() == car.theta.size());
  for (std::size_t i = 0; i < e_all.r.size(); ++i) {
    INFO("gear " << i + 1);
    CHECK(same(e_all.r[i], e_head.r[i] + e_tail.r[i]));
    CHECK(same(e_all.rvs[i], e_head.rvs[i] + e_tail.rvs[i]));
    CHECK(same(e_all.rss[i], e_head.rss[i] + e_tail.rss[i]));
    CHECK(same(e_all.rvv[i], e_head.rvv[i] + e_tail.rvv[i]));
  }
  CHECK(same(e_all.r_stand, e_head.r_stand + e_tail.r_stand));
  CHECK(same(e_all.r_stand_vv, e_head.r_stand_vv + e_tail.r_stand_vv));
  CHECK(same(e_all.r_clutch, e_head.r_clutch + e_tail.r_clutch));
  REQUIRE(e_all.r_clutch_bins.size() == p.g_density.size());
  for (std::size_t b = 0; b < e_all.r_clutch_bins.size(); ++b)
    CHECK(same(e_all.r_clutch_bins[b], e_head.r_clutch_bins[b] + e_tail.r_clutch_bins[b]));
  // Responsibilities sum to one per sample.
  double total = e_all.r_stand + e_all.r_clutch;
  for (double r : e_all.r)
    total += r;
  CHECK(total == Approx(static_cast<double>(n)).epsilon(1e-9));
}

TEST_CASE("estimator: a large log's passes run on the caller's slice runner, with the same model") {
  // Core starts no thread: the slices of each pass over a log of kParallelSamples or more go to the
  // runner in FitOptions, and the model does not depend on who runs them.
  struct CountingRunner final : SliceRunner {
    std::size_t passes = 0;
    std::size_t slices = 0;
    void run(std::size_t count, const std::function<void(std::size_t)>& task) override {
      ++passes;
      for (std::size_t i = count; i-- > 0;)  // backwards: the order must not matter
        task(i);
      slices += count;
    }
  };
  const sim::Vehicle car = sim::vehicle_preset("hatch-5");
  const auto samples =
      sim::to_samples(sim::simulate_observations(car, sim::DrivingStyle::kMixed, 50000.0, 1, 17));
  REQUIRE(samples.size() >= detail::kParallelSamples);
  CountingRunner runner;
  FitOptions options;
  options.parallel = &runner;
  const FitResult with_runner = fit_gear_model(samples, options);
  CHECK(runner.passes > 0);
  CHECK(runner.slices == 2 * runner.passes);
  const FitResult alone = fit_gear_model(samples, {});
  REQUIRE(with_runner.model.gears.size() == car.theta.size());
  CHECK(serialize_model(with_runner.model) == serialize_model(alone.model));
}
