// Entry point: validates options, keeps the usable samples, and dispatches to the paper or auto mode.
#include "core/estimator.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <tuple>
#include <vector>

#include "core/estimator_internal.hpp"

namespace gearpulse {
namespace detail {
namespace {

// Variances of theta_1..theta_M from the inverse observed information. A noise level estimated at its
// boundary (sigma -> 0) leaves the information singular in that direction; it is then held fixed (its
// rows dropped) rather than letting it poison the theta block.
Eigen::VectorXd theta_variances(const Eigen::MatrixXd& info, int gears) {
  const auto n = static_cast<int>(info.rows());
  std::vector<std::vector<int>> subsets;
  std::vector<int> all(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i)
    all[static_cast<std::size_t>(i)] = i;
  subsets.push_back(all);
  for (int drop : {gears, gears + 1}) {  // without sigma_s, then without sigma_v
    std::vector<int> sub;
    for (int i : all)
      if (i != drop) sub.push_back(i);
    subsets.push_back(sub);
  }
  std::vector<int> without_sigmas;
  for (int i = 0; i < n; ++i)
    if (i < gears || i >= gears + 2) without_sigmas.push_back(i);
  subsets.push_back(without_sigmas);
  // A weight at its bound (no clutch-out or no standstill sample in the log, e.g. a log of moving samples
  // only) makes the logits' block singular: hold the weights, then also the sigmas.
  std::vector<int> without_weights;
  for (int i = 0; i < gears + 2 && i < n; ++i)
    without_weights.push_back(i);
  subsets.push_back(without_weights);
  std::vector<int> theta_only;
  for (int i = 0; i < gears; ++i)
    theta_only.push_back(i);
  subsets.push_back(theta_only);
  for (const auto& sub : subsets) {
    const auto k = static_cast<int>(sub.size());
    Eigen::MatrixXd block(k, k);
    for (int a = 0; a < k; ++a)
      for (int b = 0; b < k; ++b)
        block(a, b) = info(sub[static_cast<std::size_t>(a)], sub[static_cast<std::size_t>(b)]);
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(block);
    if (eig.info() != Eigen::Success || eig.eigenvalues().minCoeff() <= 1e-12 * eig.eigenvalues().maxCoeff())
      continue;
    const Eigen::MatrixXd cov =
        eig.eigenvectors() * eig.eigenvalues().cwiseInverse().asDiagonal() * eig.eigenvectors().transpose();
    Eigen::VectorXd out = Eigen::VectorXd::Constant(gears, NAN);
    for (int a = 0; a < k; ++a)
      if (sub[static_cast<std::size_t>(a)] < gears) out[sub[static_cast<std::size_t>(a)]] = cov(a, a);
    return out;
  }
  return Eigen::VectorXd::Constant(gears, NAN);
}

// The median of x (the upper one of an even count).
double median_of(std::vector<double> x) {
  const auto mid = x.begin() + static_cast<std::ptrdiff_t>(x.size() / 2);
  std::nth_element(x.begin(), mid, x.end());
  return *mid;
}

}  // namespace

std::optional<IdleEstimate> estimate_idle(const MixtureData& data, std::size_t min_samples) {
  std::vector<double> idle;
  for (std::size_t i = 0; i < data.size(); ++i)
    if (data.v[i] < kStandingSpeed) idle.push_back(data.s[i]);
  if (idle.empty() || idle.size() < min_samples) return std::nullopt;
  IdleEstimate out;
  out.freq = median_of(idle);
  std::vector<double> deviation;
  deviation.reserve(idle.size());
  for (double f : idle)
    deviation.push_back(std::abs(f - out.freq));
  constexpr double kMadToSd = 1.4826;  // normal consistency factor of the median absolute deviation
  out.sd = kMadToSd * median_of(std::move(deviation));
  out.samples = idle.size();
  return out;
}

std::optional<std::size_t> gear_on_line(const GearModel& model, double speed, double freq) {
  // Within two standard deviations of eq. (4), 0.8 m/s (3 km/h) or 4 %, whichever is widest: integer km/h
  // and rpm and speed polled at different instants put a gear's samples that far off its line, while
  // adjacent gears lie 20-70 % apart (Table 1).
  constexpr double kOnLine = 0.8, kOnLineShare = 0.04;
  const std::vector<Gear>& gears = model.gears;
  if (gears.empty()) return std::nullopt;
  std::size_t best = 0;
  for (std::size_t i = 1; i < gears.size(); ++i)
    if (std::abs(gears[i].theta * freq - speed) < std::abs(gears[best].theta * freq - speed)) best = i;
  const double theta = gears[best].theta;
  const double sd = std::hypot(theta * model.sigma_freq, model.sigma_speed);
  if (std::abs(theta * freq - speed) > std::max({2.0 * sd, kOnLine, kOnLineShare * speed}))
    return std::nullopt;
  return best;
}

std::vector<GearRevs> estimate_gear_revs(const MixtureData& data, const GearModel& model) {
  // A sample counts for the gear whose line it lies on (gear_on_line). At a crawl that takes in a slipping
  // clutch and a car rolling out of gear near first gear's line: the speed synthesis has to weigh those as
  // first gear too.
  const std::vector<Gear>& gears = model.gears;
  std::vector<double> sum(gears.size(), 0.0), sum2(gears.size(), 0.0);
  std::vector<GearRevs> out(gears.size());
  for (std::size_t k = 0; k < data.size(); ++k) {
    if (data.v[k] < kMovingSpeed) continue;
    const std::optional<std::size_t> gear = gear_on_line(model, data.v[k], data.s[k]);
    if (!gear) continue;
    const double x = std::log(data.s[k]);
    sum[*gear] += x;
    sum2[*gear] += x * x;
    ++out[*gear].samples;
  }
  for (std::size_t i = 0; i < gears.size(); ++i) {
    if (out[i].samples == 0) continue;
    const auto n = static_cast<double>(out[i].samples);
    out[i].mean_log = sum[i] / n;
    out[i].sd_log = std::sqrt(std::max(sum2[i] / n - out[i].mean_log * out[i].mean_log, 0.0));
  }
  return out;
}

std::optional<IdleEstimate> estimate_rolling_idle(const MixtureData& data, const GearModel& model,
                                                  const IdleEstimate& idle, std::size_t min_samples) {
  // The rule of gear_model.hpp's rolling_idle, as the speed synthesis applies it under GPS; slowing means
  // by more than standing jitter. A gap of more than 5 s (or a new log) ends a stretch.
  using namespace rolling_idle;
  constexpr double kMaxGap = 5.0;
  const double floor = idle.freq + idle_spread(idle.freq, idle.sd);
  std::vector<double> rolling;
  std::optional<std::size_t> start;
  for (std::size_t k = 0; k < data.size(); ++k) {
    const double v = data.v[k], s = data.s[k];
    const bool candidate =
        v > kMinSpeed && s >= floor && s < kCeiling * idle.freq && !gear_on_line(model, v, s).has_value();
    const bool gap = k > 0 && (data.t[k] < data.t[k - 1] || data.t[k] - data.t[k - 1] > kMaxGap);
    if (!candidate) {
      start.reset();
    } else if (!start || gap || std::abs(s - data.s[*start]) > kFlat * data.s[*start]) {
      start = k;
    } else if (data.t[k] - data.t[*start] >= kSpan && v < data.v[*start] - kStandingSpeed) {
      rolling.push_back(s);
    }
  }
  if (rolling.size() < min_samples) return std::nullopt;
  IdleEstimate out;
  out.samples = rolling.size();
  out.freq = median_of(std::move(rolling));
  return out;
}

std::optional<DecelEstimate> estimate_idle_braking(const MixtureData& data, const GearModel& model,
                                                   const IdleEstimate& idle,
                                                   const std::optional<IdleEstimate>& rolling) {
  if (data.t.size() != data.size()) return std::nullopt;
  const double base = rolling ? std::max(idle.freq, rolling->freq) : idle.freq;
  const double ceiling = base + idle_braking::kBandSds * idle_spread(idle.freq, idle.sd);
  const auto at_idle = [&](std::size_t k) { return data.s[k] > 0.0 && data.s[k] < ceiling; };
  // Each pair runs from one sample to the first at least kMinGap later (a log sampled faster than that, as
  // at 10 Hz, gives pairs of several rows), the next pair from where it ended, all rows between at idle
  // revs. Declutched means no one gear's line holds both ends: braking at idle revs, the speed crosses
  // every gear's line at idle in turn (one sample may lie on one), while in gear the two stay on its line.
  double sum = 0.0, seconds = 0.0;
  std::size_t pairs = 0;
  std::optional<std::size_t> from;
  for (std::size_t k = 0; k < data.size(); ++k) {
    const bool in_state = at_idle(k);
    if (!in_state || (from && (data.t[k] < data.t[*from] || data.t[k] - data.t[*from] > kMaxDecelGap))) {
      from.reset();
      if (!in_state) continue;
    }
    if (!from) {
      if (data.v[k] > kMovingSpeed) from = k;
      continue;
    }
    const double dt = data.t[k] - data.t[*from];
    if (dt < idle_braking::kMinGap) continue;
    const auto line_from = gear_on_line(model, data.v[*from], data.s[*from]);
    const bool declutched = !line_from || line_from != gear_on_line(model, data.v[k], data.s[k]);
    if (declutched) {
      // Measured and weighed as under GPS (SynthHabits::learn).
      const double a = idle_braking::clip((data.v[k] - data.v[*from]) / dt);
      const double w = idle_braking::weight(dt);
      sum += w * a;
      seconds += w;
      ++pairs;
    }
    from.reset();
    if (data.v[k] > kMovingSpeed) from = k;
  }
  if (pairs == 0) return std::nullopt;
  return DecelEstimate{sum / seconds, seconds, pairs};
}

GearModel finish_model(const MixtureData& data, const MixtureParams& p, const std::string& method,
                       const GradientLayout& layout) {
  GearModel model;
  model.method = method;
  model.samples = data.size();
  model.sigma_speed = p.sigma_v;
  model.sigma_freq = p.sigma_s;
  model.outlier_weight = p.beta_clutch;
  model.log_likelihood = log_likelihood(data, p);
  const Eigen::MatrixXd info = observed_information(data, p, layout);
  const Eigen::VectorXd variance = theta_variances(info, p.gears());
  for (int i = 0; i < p.gears(); ++i) {
    Gear g;
    g.theta = p.theta[static_cast<std::size_t>(i)];
    g.weight = p.alpha[static_cast<std::size_t>(i)];
    // A non-positive variance means the information matrix is singular there: report 0 (unknown)
    // rather than a fabricated figure.
    g.std_error = std::isfinite(variance[i]) && variance[i] > 0.0 ? std::sqrt(variance[i]) : 0.0;
    model.gears.push_back(g);
  }
  nlohmann::json clutch = {
      {"weight", p.beta_clutch}, {"lo", p.g_lo}, {"hi", p.g_hi}, {"density", p.g_density}};
  model.extra["clutch_out"] = clutch;
  if (p.beta_stand > 0.0) model.extra["standstill"] = {{"weight", p.beta_stand}, {"sigma", p.stand_sigma}};
  return model;
}

}  // namespace detail

bool detail::holds_values(const MixtureData& data) {
  const std::size_t n = data.size();
  if (data.t.size() != n) return false;
  // A logger that holds values: its moving rows mostly bring one new value of the two (a GPS and a tracker
  // read at every row change both).
  constexpr double kHeldShare = 0.2;
  std::size_t pairs = 0, one_new = 0;
  for (std::size_t k = 1; k < n; ++k) {
    const double dt = data.t[k] - data.t[k - 1];
    if (!(data.v[k] > 0.0 && data.v[k - 1] > 0.0) || !(dt > 0.0 && dt <= kHeldSpan)) continue;
    ++pairs;
    one_new += (data.v[k] == data.v[k - 1]) != (data.s[k] == data.s[k - 1]) ? 1 : 0;
  }
  return pairs > 0 && static_cast<double>(one_new) >= kHeldShare * static_cast<double>(pairs);
}

void detail::interpolate_held(MixtureData& data) {
  const std::size_t n = data.size();
  if (data.t.size() != n) return;
  auto fill = [&](std::vector<double>& x) {
    std::size_t last = 0;  // first sample of the current run of one value (when it was polled)
    for (std::size_t k = 1; k <= n; ++k) {
      if (k < n && x[k] == x[last] && data.t[k] >= data.t[k - 1]) continue;
      // [last, k) hold one value; k (if any) brings the next one. A speed of 0 is a car standing.
      if (k < n && k > last + 1 && x[last] != 0.0 && data.t[k] > data.t[last] &&
          data.t[k] - data.t[last] <= kHeldSpan) {
        const double span = data.t[k] - data.t[last];
        for (std::size_t j = last + 1; j < k; ++j)
          x[j] = x[last] + (x[k] - x[last]) * (data.t[j] - data.t[last]) / span;
      }
      last = k;
    }
  };
  fill(data.v);
  fill(data.s);
}

// Logs no gear ladder can be read from: every sample at one instant, or a speed or an engine frequency
// that hardly changes while the car moves (a ladder is read from the two changing together; a frequency
// that changes at one speed is no more than one gear told from its neighbour). Real drives spread both
// widely (the Etios logs: engine frequency 1.7-2.7x from the 10th to the 90th percentile). Returns the
// reason, empty if the log is usable.
std::string detail::degenerate_log(const detail::MixtureData& data) {
  if (data.t.size() == data.size() && data.size() >= 2 &&
      std::all_of(data.t.begin(), data.t.end(), [&](double t) { return t == data.t.front(); }))
    return "every sample has the same time stamp";
  std::vector<double> moving_freq, moving_speed;
  for (std::size_t k = 0; k < data.size(); ++k) {
    if (data.v[k] > detail::kMovingSpeed) {
      moving_freq.push_back(data.s[k]);
      moving_speed.push_back(data.v[k]);
    }
  }
  if (moving_freq.size() < 30) return {};  // too little to judge: the fit says so itself
  constexpr double kMinSpread = 1.15;
  const auto narrow = [](std::vector<double>& x) {
    std::sort(x.begin(), x.end());
    return x[x.size() - 1 - x.size() / 10] < kMinSpread * x[x.size() / 10];
  };
  if (narrow(moving_freq))
    return "the engine frequency hardly changes while the car moves (10th-90th percentile within 15 %): no "
           "gear ladder can be read from it";
  if (narrow(moving_speed))
    return "the speed hardly changes (10th-90th percentile within 15 %): no gear ladder can be read from it";
  return {};
}

FitResult fit_gear_model(std::span<const Sample> samples, const FitOptions& options) {
  if (!options.ratios.empty()) {
    if (options.ratios.size() + 1 > GearModel::kMaxGears)
      throw std::invalid_argument("fit: at most " + std::to_string(GearModel::kMaxGears - 1) + " ratios (" +
                                  std::to_string(GearModel::kMaxGears) + " gears)");
    // Adjacent gears of a road vehicle differ by some percent up to about twice (Table 1: 1.22-1.68).
    for (double c : options.ratios) {
      if (!std::isfinite(c) || c < 1.05 || c > 4.0)
        throw std::invalid_argument("fit: every ratio must lie in [1.05, 4]");
    }
    if (options.gears != 0 && options.gears != static_cast<int>(options.ratios.size()) + 1)
      throw std::invalid_argument("fit: --gears must equal the number of ratios + 1");
  }
  if (options.gears != 0 && (options.gears < 2 || options.gears > static_cast<int>(GearModel::kMaxGears)))
    throw std::invalid_argument("fit: gears must be 2.." + std::to_string(GearModel::kMaxGears) +
                                " (or 0 = from the data)");
  const auto usable = [](const Sample& s) {
    return s.has_speed() && s.has_freq() && s.speed >= 0.0 && s.freq > 0.0 && std::isfinite(s.speed / s.freq);
  };
  // A record that repeats an earlier one whole (time, speed and frequency) is that observation read
  // again: the same log given twice, overlapping exports, one drive joined to itself. Observations count
  // once in the likelihood; a copy would make every count-based judgement (the least support of a gear,
  // the samples a valley is judged on, the selection criterion's sample size) see more evidence than
  // the driving gave, so the ladder would depend on how often one drive was read. Later copies go.
  std::vector<bool> copy(samples.size(), false);
  {
    std::vector<std::size_t> order;
    order.reserve(samples.size());
    for (std::size_t i = 0; i < samples.size(); ++i)
      if (usable(samples[i]) && std::isfinite(samples[i].t)) order.push_back(i);
    const auto key = [&](std::size_t i) {
      return std::tuple(samples[i].t, samples[i].speed, samples[i].freq);
    };
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return key(a) < key(b); });
    for (std::size_t j = 1; j < order.size(); ++j)
      if (key(order[j]) == key(order[j - 1])) copy[order[j]] = true;
  }
  detail::MixtureData data;
  data.parallel = options.parallel;
  data.stop = options.stop;
  data.v.reserve(samples.size());
  data.s.reserve(samples.size());
  data.t.reserve(samples.size());
  // A row repeating both values of the one before carries nothing new: loggers that poll slower than they
  // write (OBD) repeat held values, and counting each copy would make the fit as sure of them as of
  // fresh readings. Within a poll's reach only: the same values kHeldFor after they were read are a
  // reading again (a steady cruise or a car at rest logged with rounded values), as replay counts them.
  constexpr double kHeldFor = 3.0;  // s
  double last_speed = -1.0, last_freq = -1.0, last_t = -std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const Sample& s = samples[i];
    if (!usable(s) || copy[i]) continue;
    if (s.speed == last_speed && s.freq == last_freq && s.t - last_t < kHeldFor) continue;
    last_speed = s.speed;
    last_freq = s.freq;
    last_t = s.t;
    data.v.push_back(s.speed);
    data.s.push_back(s.freq);
    data.t.push_back(s.t);
  }
  FitResult result;
  if (const std::string problem = detail::degenerate_log(data); !problem.empty()) {
    result.model.method = options.ratios.empty() ? "auto" : "paper";
    result.model.samples = data.size();
    result.model.reason = problem;
    return result;
  }
  bool polled = false;  // a polling logger's log (holds_values)
  {
    // The ladder from speed and frequency as of one instant; what the driver does (idle, revs per gear,
    // rolling idle) below from the values as logged, as the synthesis sees them live.
    std::optional<detail::MixtureData> aligned;
    if (detail::holds_values(data)) {
      aligned = data;
      detail::interpolate_held(*aligned);
    }
    const detail::MixtureData& fit_data = aligned ? *aligned : data;
    polled = aligned.has_value();
    if (!options.ratios.empty()) {
      result.model = detail::fit_paper(fit_data, options.ratios);
    } else {
      result.model = detail::fit_auto(fit_data, options.gears, options.single_gear);
      // The gears below the ladder that more gears held (extra.lower_gears) are launch gears, passed in a
      // second or two: between polls seconds apart the line misses a launch's speed by more than a gear
      // step, and a polled log's clusters there are its polls' as much as a gear's.
      if (aligned) result.model.extra.erase("lower_gears");
    }
  }
  if (result.model.method.empty()) result.model.method = options.ratios.empty() ? "auto" : "paper";
  // A ladder is only handed out if it is one (eq. (5)): positive, finite, strictly ascending thetas. An
  // optimiser driven to a bound by absurd data or priors gives no model rather than a broken one.
  for (std::size_t i = 0; i < result.model.gears.size(); ++i) {
    const double theta = result.model.gears[i].theta;
    if (!std::isfinite(theta) || theta <= 0.0 || (i > 0 && theta <= result.model.gears[i - 1].theta)) {
      result.model.gears.clear();
      result.model.reason = "the fit did not reach a valid gear ladder (thetas not positive and ascending)";
      break;
    }
  }
  if (result.model.samples == 0) result.model.samples = data.size();
  // The engine's idle, from the samples standing still: the speed synthesis needs it to tell a car at a
  // light from one rolling in a high gear before GPS has shown it standing.
  constexpr std::size_t kMinIdleSamples = 10;
  const auto idle = detail::estimate_idle(data, kMinIdleSamples);
  if (idle) result.model.extra["idle"] = {{"freq", idle->freq}, {"sd", idle->sd}, {"samples", idle->samples}};
  // How this driver uses each gear (the engine frequencies it runs at): the speed synthesis weighs a gear
  // that explains the revs by how usual those revs are in it.
  if (!result.model.gears.empty()) {
    nlohmann::json revs = nlohmann::json::array();
    for (const detail::GearRevs& r : detail::estimate_gear_revs(data, result.model))
      revs.push_back({{"mean_log", r.mean_log}, {"sd_log", r.sd_log}, {"samples", r.samples}});
    result.model.extra["revs"] = std::move(revs);
    // The revs the engine is held at while the car rolls declutched, above its standing idle.
    if (idle) {
      const auto rolling = detail::estimate_rolling_idle(data, result.model, *idle, kMinIdleSamples);
      if (rolling)
        result.model.extra["rolling_idle"] = {{"freq", rolling->freq}, {"samples", rolling->samples}};
      // How hard this driver slows declutched with the engine at idle: the synthesis' prior for it.
      if (const auto braking = detail::estimate_idle_braking(data, result.model, *idle, rolling))
        result.model.extra["idle_braking"] = {
            {"accel", braking->accel}, {"seconds", braking->seconds}, {"samples", braking->samples}};
      // How many gears the launches pass below the ladder's lowest: the synthesis' count to start from.
      if (const auto launches =
              polled ? detail::estimate_launch_gears(data, result.model, *idle) : std::nullopt)
        result.model.extra["launch_gears"] = {{"base", launches->base_theta}, {"counts", launches->counts}};
    }
  }
  return result;
}

namespace {

// The line gps = slope x wheel + offset through pairs of speeds (Theil-Sen: the median of the pairwise
// slopes, then the median offset), robust to GPS lag in accelerations and to a logger's rounding.
std::pair<double, double> speed_line(const std::vector<std::pair<double, double>>& pairs) {
  constexpr std::size_t kMaxPairs = 1500;  // a stride over longer logs: 1.1 M slopes at most
  std::vector<std::pair<double, double>> use;
  const std::size_t stride = (pairs.size() + kMaxPairs - 1) / kMaxPairs;
  for (std::size_t i = 0; i < pairs.size(); i += stride)
    use.push_back(pairs[i]);
  constexpr double kMinSpan = 1.0;  // m/s of wheel speed between two pairs for a slope
  std::vector<double> slopes;
  for (std::size_t i = 0; i < use.size(); ++i)
    for (std::size_t j = i + 1; j < use.size(); ++j) {
      const double dw = use[j].first - use[i].first;
      if (std::abs(dw) >= kMinSpan) slopes.push_back((use[j].second - use[i].second) / dw);
    }
  if (slopes.empty()) return {1.0, 0.0};
  const double slope = detail::median_of(std::move(slopes));
  std::vector<double> offsets;
  for (const auto& [w, g] : use)
    offsets.push_back(g - slope * w);
  return {slope, detail::median_of(std::move(offsets))};
}

}  // namespace

FitResult fit_gear_model_two_speeds(std::span<const TwoSpeedLog> logs, const FitOptions& options) {
  constexpr double kMinSpeed = 2.0;  // m/s: GPS Doppler is coarse at a crawl
  constexpr std::size_t kMinPairs = 30;
  constexpr double kSteady = 1.0;                // m/s of change between the rows before and after
  constexpr double kMaxSpan = 3.0;               // s between them
  std::vector<std::pair<double, double>> pairs;  // (wheel, gps) at one instant
  std::vector<Sample> gps, wheel;
  for (const TwoSpeedLog& log : logs) {
    gps.insert(gps.end(), log.gps.begin(), log.gps.end());
    wheel.insert(wheel.end(), log.wheel.begin(), log.wheel.end());
    // Both readings of a row carry its t; the readers keep rows in file order (t never falls). Only rows
    // where the wheel speed holds count: GPS lags a changing speed.
    const std::span<const Sample> ws = log.wheel;
    std::size_t j = 0;
    for (const Sample& g : log.gps) {
      while (j < ws.size() && ws[j].t < g.t)
        ++j;
      if (j + 1 >= ws.size()) break;
      if (j == 0 || ws[j].t != g.t || !g.has_speed() || !(g.speed > kMinSpeed)) continue;
      const Sample &before = ws[j - 1], &w = ws[j], &after = ws[j + 1];
      const bool steady = w.speed > kMinSpeed && after.t - before.t <= kMaxSpan &&
                          std::abs(after.speed - before.speed) <= kSteady;
      if (steady) pairs.emplace_back(w.speed, g.speed);
    }
  }
  FitResult on_gps = fit_gear_model(gps, options);
  // A ladder only the wheel speed shows is not taken: an automatic's lock-up clutch can hold two tight
  // ratio clusters in the smooth wheel speed that GPS sees as the continuum they belong to.
  if (pairs.size() < kMinPairs || on_gps.model.gears.empty()) return on_gps;
  const auto [slope, offset] = speed_line(pairs);
  if (!(slope > 0.5 && slope < 2.0)) return on_gps;  // not the same car's speed
  for (Sample& w : wheel)
    if (w.has_speed() && w.speed > 0.0) w.speed = std::max(slope * w.speed + offset, 0.0);
  FitResult result = fit_gear_model(wheel, options);
  // Whole km/h can blur a low gear that GPS resolves: the reading that shows more of the ladder wins.
  if (result.model.gears.size() < on_gps.model.gears.size()) return on_gps;
  result.model.extra["speed_scale"] = {
      {"from", "wheel"}, {"slope", slope}, {"offset", offset}, {"pairs", pairs.size()}};
  return result;
}

}  // namespace gearpulse
