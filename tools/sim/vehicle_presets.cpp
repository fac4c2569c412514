// Vehicle presets. Apart from the paper's BMW, the ladders are invented but plausible: gearbox ratios of
// common cars divided into a top-gear scale, the engine component being the crank frequency (rpm / 60).
#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>

#include "tools/sim/vehicle_sim.hpp"

namespace gearpulse::sim {
namespace {

// theta_i = top_theta * ratio_top / ratio_i: m/s per Hz scales inversely with the overall ratio.
std::vector<double> ladder(double top_theta, std::initializer_list<double> ratios) {
  std::vector<double> r(ratios);
  std::vector<double> theta;
  for (auto it = r.rbegin(); it != r.rend(); ++it)
    theta.insert(theta.begin(), top_theta * r.back() / *it);
  return theta;
}

Vehicle crank_vehicle(std::string name, std::vector<double> theta) {
  Vehicle v;
  v.name = std::move(name);
  v.theta = std::move(theta);
  v.idle_freq = 13.3;  // 800 rpm
  v.max_freq = 100.0;  // 6000 rpm
  v.upshift_freq = 42.0;
  v.downshift_freq = 22.0;
  return v;
}

}  // namespace

Vehicle bmw_520i() {
  Vehicle v;
  v.name = "bmw-520i";
  v.theta = {0.043, 0.072, 0.106, 0.146, 0.178};  // Table 3, reference estimates
  // The paper tracked a component in 50-200 Hz (section 4); at 100 km/h in 5th that is 156 Hz, i.e. the
  // third crank harmonic of a straight six, so idle 750 rpm is 37.5 Hz.
  v.idle_freq = 37.5;
  v.max_freq = 300.0;
  v.upshift_freq = 130.0;
  v.downshift_freq = 65.0;
  v.max_accel = 2.8;
  return v;
}

std::vector<Vehicle> vehicle_presets() {
  std::vector<Vehicle> out;
  out.push_back(bmw_520i());
  // Etios-like small hatch: 1000 rpm in 5th ~ 35 km/h; ratios 3.55/1.90/1.31/1.03/0.80.
  out.push_back(crank_vehicle("hatch-5", ladder(0.583, {3.545, 1.904, 1.310, 1.031, 0.795})));
  // Close-ratio sports 6-speed: steps 1.29 .. 1.21.
  out.push_back(crank_vehicle("close-6", ladder(0.50, {3.10, 2.40, 1.90, 1.55, 1.27, 1.05})));
  // Wide-ratio 4-speed utility: steps 1.77, 1.56, 1.38.
  {
    Vehicle v = crank_vehicle("wide-4", ladder(0.45, {3.80, 2.15, 1.38, 1.00}));
    v.max_freq = 83.0;  // 5000 rpm diesel-like
    v.upshift_freq = 38.0;
    v.downshift_freq = 20.0;
    out.push_back(std::move(v));
  }
  // Van 6-speed: a very short first (1.92 step), then 1.71, 1.52, 1.25, 1.23.
  out.push_back(crank_vehicle("van-6", ladder(0.62, {5.00, 2.60, 1.52, 1.00, 0.80, 0.65})));
  // 7-speed: 1.56, 1.45, 1.29, 1.31, 1.30, 1.19.
  out.push_back(crank_vehicle("sport-7", ladder(0.66, {5.00, 3.20, 2.20, 1.70, 1.30, 1.00, 0.84})));
  // Old compact 4-speed: 3.45/1.94/1.29/0.91 (steps 1.78, 1.50, 1.42).
  out.push_back(crank_vehicle("compact-4", ladder(0.46, {3.45, 1.94, 1.29, 0.91})));
  {
    Vehicle v = crank_vehicle("cvt", {});
    v.cvt_theta_min = 0.10;
    v.cvt_theta_max = 0.62;
    out.push_back(std::move(v));
  }
  return out;
}

Vehicle random_vehicle(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  auto uniform = [&rng](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  const int gears = std::uniform_int_distribution<int>(4, 7)(rng);
  // Overall spread first / top and how progressive the steps are: step i (from the bottom) is
  // proportional in log to (1 + progression)^((gears - 2 - i) / (gears - 1)).
  const double spread = uniform(3.0, 5.2);
  const double progression = uniform(0.5, 1.0);
  std::vector<double> weight(static_cast<std::size_t>(gears - 1));
  double weight_sum = 0.0;
  for (int i = 0; i + 1 < gears; ++i) {
    weight[static_cast<std::size_t>(i)] =
        std::pow(1.0 + progression, static_cast<double>(gears - 2 - i) / static_cast<double>(gears - 1));
    weight_sum += weight[static_cast<std::size_t>(i)];
  }
  // The component tracked: the crank frequency (what OBD rpm / 60 gives), or a firing frequency (an
  // engine of 4, 6, 8 or 12 cylinders fires 2, 3, 4 or 6 times per turn), where the lighter's ripple is.
  static constexpr double kMultiples[] = {1.0, 2.0, 2.0, 3.0, 4.0, 6.0};
  const double multiple = kMultiples[std::uniform_int_distribution<int>(0, 5)(rng)];
  const double top_theta = uniform(0.40, 0.70) / multiple;  // m/s per Hz of the component, top gear
  Vehicle v;
  v.name = "random-" + std::to_string(seed);
  // theta from the top down: each step divides by exp(log(spread) * weight / weight_sum).
  v.theta.assign(static_cast<std::size_t>(gears), top_theta);
  for (int i = gears - 2; i >= 0; --i)
    v.theta[static_cast<std::size_t>(i)] =
        v.theta[static_cast<std::size_t>(i + 1)] /
        std::exp(std::log(spread) * weight[static_cast<std::size_t>(i)] / weight_sum);
  v.idle_freq = uniform(11.5, 15.0) * multiple;  // 700-900 rpm
  v.max_freq = uniform(75.0, 110.0) * multiple;  // 4500-6600 rpm
  // Shift points relative to idle: up at 2.2-4x idle (about 1700-3300 rpm), down at 1.35-2x idle (about
  // 1000-1700 rpm, the low end a frugal driver's or a diesel's), at most two thirds of the way up.
  v.upshift_freq = uniform(2.2, 4.0) * v.idle_freq;
  v.downshift_freq = std::min(uniform(1.35, 2.0) * v.idle_freq, 0.67 * v.upshift_freq);
  v.max_accel = uniform(1.8, 3.4);
  return v;
}

Vehicle wide_vehicle(std::uint64_t seed) {
  std::mt19937_64 rng(seed ^ 0x77696465ULL);  // a stream of its own: wide-N is no relative of random-N
  auto uniform = [&rng](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  auto pick = [&rng](int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng); };
  // The kind of engine and gearbox: a petrol car (3-speed to 9-speed), a diesel car or light van (low
  // idle, low rev limit), a motorcycle (high idle and rev limit, 5-6 close gears).
  const int kind = pick(0, 2);
  // The component tracked, in multiples of the crank frequency: the crank itself, or the firing
  // frequency of cylinders / 2 fires per turn (a single 0.5, a triple 1.5, a five 2.5, a V8 4).
  static constexpr double kCarMultiples[] = {1.0, 1.5, 2.0, 2.5, 3.0, 4.0};
  static constexpr double kBikeMultiples[] = {0.5, 1.0, 1.5, 2.0};
  const double multiple = kind == 2 ? kBikeMultiples[pick(0, 3)] : kCarMultiples[pick(0, kind == 1 ? 4 : 5)];
  // Idle and rev limit, rpm: a petrol car 650-1000 / 5000-7000, a diesel 600-850 / 3800-4800, a
  // motorcycle 1100-1500 / 8500-12500.
  const double idle_rpm = kind == 0   ? uniform(650, 1000)
                          : kind == 1 ? uniform(600, 850)
                                      : uniform(1100, 1500);
  const double max_rpm = kind == 0   ? uniform(5000, 7000)
                         : kind == 1 ? uniform(3800, 4800)
                                     : uniform(8500, 12500);
  const int gears = kind == 0 ? pick(3, 9) : kind == 1 ? pick(5, 8) : pick(5, 6);
  // Spread first / top: a car's first gear launches it (about 13-18:1 overall) and its top cruises
  // (2.5-4:1), so 2.8x at least, up to 8x with a crawler first; adjacent steps of 1.2-1.8 bound it by the
  // gear count. A motorcycle's power to weight lets first be tall: 2.3-3.2x.
  const double spread =
      kind == 2 ? uniform(2.3, 3.2)
                : uniform(std::max(2.8, std::pow(1.2, gears - 1)), std::min(8.0, std::pow(1.8, gears - 1)));
  // Log-steps from the bottom: progressive (shrinking toward the top) as random_vehicle's, each moved by
  // up to 30 %, and one in two ladders with a quirk: a crawler first, two close top gears, a tall overdrive.
  std::vector<double> weight(static_cast<std::size_t>(gears - 1));
  const double progression = uniform(0.0, 1.0);
  for (int i = 0; i + 1 < gears; ++i)
    weight[static_cast<std::size_t>(i)] =
        std::pow(1.0 + progression, -static_cast<double>(i) / (gears - 1)) * uniform(0.7, 1.3);
  const int quirk = pick(0, 5);
  if (quirk == 0) weight.front() *= 2.5;              // crawler first
  if (quirk == 1 && gears > 3) weight.back() *= 0.3;  // two close top gears
  if (quirk == 2 && gears > 3) weight.back() *= 1.8;  // tall overdrive
  double weight_sum = 0.0;
  for (double w : weight)
    weight_sum += w;
  // Top gear's road speed per 1000 rpm: a petrol car's 28-45 km/h, a diesel's overdrive 35-55 km/h, a
  // motorcycle's 18-28 km/h (what cruising at 130 km/h and the top speed near the rev limit ask).
  const double kmh_per_1000 = kind == 0 ? uniform(28, 45) : kind == 1 ? uniform(35, 55) : uniform(18, 28);
  const double top_theta = kmh_per_1000 / 3.6 / (1000.0 / 60.0 * multiple);  // m/s per Hz of the component
  Vehicle v;
  v.name = "wide-family-" + std::to_string(seed);
  v.theta.assign(static_cast<std::size_t>(gears), top_theta);
  // Each step between 1.07 (the closest gearboxes' top pairs) and 2.5 (a crawler under a wide first).
  for (int i = gears - 2; i >= 0; --i)
    v.theta[static_cast<std::size_t>(i)] =
        v.theta[static_cast<std::size_t>(i + 1)] /
        std::clamp(std::exp(std::log(spread) * weight[static_cast<std::size_t>(i)] / weight_sum), 1.07, 2.5);
  v.idle_freq = idle_rpm / 60.0 * multiple;
  v.max_freq = max_rpm / 60.0 * multiple;
  // Shift points relative to idle as random_vehicle's (up at 2.2-4x idle, down at 1.35-2x), the upshift
  // below 70 % of the rev limit (a diesel's narrow band).
  v.upshift_freq = std::min(uniform(2.2, 4.0) * v.idle_freq, 0.7 * v.max_freq);
  v.downshift_freq = std::min(uniform(1.35, 2.0) * v.idle_freq, 0.67 * v.upshift_freq);
  v.max_accel = kind == 2 ? uniform(3.0, 5.0) : kind == 1 ? uniform(1.4, 2.6) : uniform(1.8, 3.4);
  return v;
}

Vehicle vehicle_preset(std::string_view name) {
  for (Vehicle& v : vehicle_presets()) {
    if (v.name == name) return std::move(v);
  }
  throw std::invalid_argument("unknown vehicle preset '" + std::string(name) + "'");
}

std::string_view style_name(DrivingStyle style) noexcept {
  switch (style) {
    case DrivingStyle::kMixed:
      return "mixed";
    case DrivingStyle::kUrban:
      return "urban";
    case DrivingStyle::kHighway:
      return "highway";
    case DrivingStyle::kTrafficJam:
      return "jam";
  }
  return "mixed";
}

DrivingStyle parse_style(std::string_view name) {
  if (name == "mixed") return DrivingStyle::kMixed;
  if (name == "urban") return DrivingStyle::kUrban;
  if (name == "highway") return DrivingStyle::kHighway;
  if (name == "jam" || name == "traffic-jam") return DrivingStyle::kTrafficJam;
  throw std::invalid_argument("unknown driving style '" + std::string(name) + "'");
}

}  // namespace gearpulse::sim
