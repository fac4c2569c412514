#include "core/mode_filter.hpp"

#include <algorithm>
#include <cmath>

namespace gearpulse {
namespace {

constexpr double kPi = 3.14159265358979323846;
// Outlier share of the frequency: a confident tracker hop on something else than the engine line, a few
// percent of hops. GPS speed is taken as it comes (a receiver's Doppler speed is seldom grossly wrong): a
// mode whose track rejected fixes as outliers would keep a speed no fix supports.
constexpr double kFreqOutlier = 0.03;
// In gear, v = theta f up to the tyres' slip and the driveline's wind-up: about 1 %.
constexpr double kSlip = 0.01;
// Declutched and rolling, the revs sit at idle about half the time (coasting) and anywhere below the revs
// seen otherwise (falling after a shift, blipped); standing, at idle but for a blip now and then.
constexpr double kIdleShareRolling = 0.5, kIdleShareStanding = 0.9;
// Moving off, the slipping clutch holds the revs above idle, up to three times it.
constexpr double kLaunchRevs = 3.0;
// A move-off given up (stalled, the light stayed red): rare against the bite.
constexpr double kAbortRate = 0.05;  // 1/s
// Below this speed (m/s) the declutched car is standing: what follows is a move-off, the clutch biting in
// first gear (or second, for some drivers).
constexpr double kStanding = 1.0;
constexpr double kLaunchSecond = 0.1;
constexpr double kMinProb = 1e-12;

double log_normal(double y, double var) noexcept {
  return -0.5 * (std::log(2.0 * kPi * var) + y * y / var);
}

// Kalman update of a track by a reading z of its speed with variance r that stands for `weight` (0..1] of an
// independent reading, robust to an outlier share eps spread over `range`. The reading's density is
// tempered, N(z; v, r)^weight, whose integral over the track's speed is the Gaussian of variance
// pvv + r / weight times the normalisation below: a step's share of a correlated reading weighs its noise by
// that share, and the track's own speed uncertainty in full. Returns the log-likelihood.
double robust_update(SpeedTrack& x, double z, double r, double eps, double range, double weight) noexcept {
  const double y = z - x.v;
  const double log_norm = 0.5 * (std::log(2.0 * kPi * r / weight) - weight * std::log(2.0 * kPi * r));
  const double log_in = std::log(1.0 - eps) + log_normal(y, x.pvv + r / weight) + log_norm;
  const double log_out = eps > 0.0 ? weight * std::log(eps / range) : -INFINITY;
  const double top = std::max(log_in, log_out);
  const double log_l = top + std::log(std::exp(log_in - top) + std::exp(log_out - top));
  const double w = weight * std::exp(log_in - log_l);  // the reading's weight times its odds of no outlier
  if (w > 1e-9) {
    const double sw = x.pvv + r / w;
    const double kv = x.pvv / sw, ka = x.pva / sw;
    x.v += kv * y;
    x.a += ka * y;
    const double pvv = x.pvv, pva = x.pva;
    x.pvv = pvv - kv * pvv;
    x.pva = pva - kv * pva;
    x.paa -= ka * pva;
  }
  return log_l;
}

}  // namespace

void ModeFilter::reset() noexcept {
  prob_.fill(0.0);
  const int n = modes();
  prob_[0] = 0.5;
  for (int g = 1; g < n; ++g)
    prob_[static_cast<std::size_t>(g)] = 0.5 / (n - 1);
  if (n == 1) prob_[0] = 1.0;
  track_.fill(SpeedTrack{});
}

void ModeFilter::set_ladder(const GearLadder& ladder) noexcept {
  ModeArray prob{};
  std::array<SpeedTrack, kMaxModes> track{};
  track.fill(track_[0]);
  prob[0] = prob_[0];
  prob[ladder.gears + 1] = prob_[launch()];
  track[ladder.gears + 1] = track_[launch()];
  ModeArray best{};  // the largest belief carried into each new gear, whose track it takes
  for (int g = 1; g <= ladder_.gears; ++g) {
    if (ladder.gears == 0) {  // no ladder: every gear's belief goes to the clutch
      prob[0] += prob_[g];
      continue;
    }
    int nearest = 1;
    for (int k = 1; k <= ladder.gears; ++k)
      if (std::abs(std::log(ladder.theta[k] / ladder_.theta[g])) <
          std::abs(std::log(ladder.theta[nearest] / ladder_.theta[g])))
        nearest = k;
    const auto n = static_cast<std::size_t>(nearest);
    prob[n] += prob_[g];
    if (prob_[g] >= best[n]) best[n] = prob_[g], track[n] = track_[g];
  }
  ladder_ = ladder;
  double total = 0.0;
  for (int m = 0; m < modes(); ++m)
    total += prob[m];
  if (!(total > 0.0)) {
    track_ = track;
    reset();
    track_ = track;
    return;
  }
  for (int m = 0; m < modes(); ++m)
    prob[m] /= total;
  prob_ = prob;
  track_ = track;
}

double ModeFilter::entry_weight(int gear, double speed, const DrivingHabits& habits) const noexcept {
  if (!std::isfinite(habits.gear_revs_mean[gear])) return 1.0;
  // The gear whose revs at this speed sit in the band this driver runs it in; a floor keeps every gear
  // possible.
  const double z =
      (std::log(speed / ladder_.theta[gear]) - habits.gear_revs_mean[gear]) / habits.gear_revs_sd[gear];
  return std::exp(-0.5 * z * z) + 1e-3;
}

void ModeFilter::transition_matrix(double dt, const DrivingHabits& habits) noexcept {
  const int n = modes();
  Matrix& q = scratch_;
  for (int i = 0; i < n; ++i)
    q[i].fill(0.0);
  const int gears = ladder_.gears;
  for (int g = 1; g <= gears; ++g) {
    const double rate = habits.leave_rate[g];
    const auto& share = habits.shift_share;
    double declutch = share[static_cast<int>(ShiftKind::kDeclutch)];
    auto spread = [&](int lo, int hi, double s) {
      if (lo > hi) return s;  // no such gear: the share goes to the clutch
      for (int k = lo; k <= hi; ++k)
        q[g][k] += rate * s / (hi - lo + 1);
      return 0.0;
    };
    declutch += spread(g + 1, std::min(g + 1, gears), share[static_cast<int>(ShiftKind::kUp)]);
    declutch += spread(std::max(g - 1, 1), g - 1, share[static_cast<int>(ShiftKind::kDown)]);
    declutch += spread(g + 2, gears, share[static_cast<int>(ShiftKind::kSkipUp)]);
    declutch += spread(1, g - 2, share[static_cast<int>(ShiftKind::kSkipDown)]);
    q[g][0] += rate * declutch;
  }
  if (gears > 0) {
    const double v = track_[0].v;
    if (v < kStanding) {
      q[0][launch()] = habits.launch_rate;
    } else {
      double total = 0.0;
      for (int g = 1; g <= gears; ++g)
        total += entry_weight(g, v, habits);
      for (int g = 1; g <= gears; ++g)
        q[0][g] = habits.engage_rate * entry_weight(g, v, habits) / total;
    }
    const double second = gears > 1 ? kLaunchSecond : 0.0;
    q[launch()][1] = habits.bite_rate * (1.0 - second);
    if (gears > 1) q[launch()][2] = habits.bite_rate * second;
    q[launch()][0] = kAbortRate;
  }
  double norm = 0.0;
  for (int i = 0; i < n; ++i) {
    double out = 0.0;
    for (int j = 0; j < n; ++j)
      out += q[i][j];
    q[i][i] = -out;
    norm = std::max(norm, 2.0 * out * dt);
  }
  // exp(Q dt) by scaling and squaring: a Taylor series of Q dt / 2^s (norm <= 1/4, error < 1e-5), squared
  // s times.
  int squarings = 0;
  while (norm > 0.25 && squarings < 40)
    norm *= 0.5, ++squarings;
  const double scale = dt / std::ldexp(1.0, squarings);
  Matrix& e = trans_;
  for (int i = 0; i < n; ++i) {
    e[i].fill(0.0);
    e[i][i] = 1.0;
    for (int j = 0; j < n; ++j)
      q[i][j] *= scale;
  }
  // Horner: I + A (I + A/2 (I + A/3 (I + A/4)))
  Matrix& term = power_;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      term[i][j] = (i == j ? 1.0 : 0.0) + q[i][j] / 4.0;
  for (int k = 3; k >= 1; --k) {
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        double s = 0.0;
        for (int m = 0; m < n; ++m)
          s += q[i][m] * term[m][j];
        e[i][j] = (i == j ? 1.0 : 0.0) + s / k;
      }
    if (k > 1)
      for (int i = 0; i < n; ++i)
        term[i] = e[i];
  }
  for (int s = 0; s < squarings; ++s) {
    for (int i = 0; i < n; ++i)
      term[i] = e[i];
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        double sum = 0.0;
        for (int m = 0; m < n; ++m)
          sum += term[i][m] * term[m][j];
        e[i][j] = sum;
      }
  }
  for (int i = 0; i < n; ++i) {
    double total = 0.0;
    for (int j = 0; j < n; ++j)
      total += e[i][j] = std::max(e[i][j], 0.0);
    for (int j = 0; j < n; ++j)
      e[i][j] /= total;
  }
}

ModeFilter::Acceleration ModeFilter::acceleration(int mode, const DrivingHabits& habits) const noexcept {
  if (mode == 0) return {habits.coast_accel, habits.coast_sd};
  if (mode == launch()) return {habits.launch_accel, habits.launch_sd};
  return {0.0, habits.accel_sd};
}

void ModeFilter::predict(SpeedTrack& x, int mode, double dt, const DrivingHabits& habits) const noexcept {
  if (dt <= 0.0) return;
  if (mode == 0 && x.v < kStanding) {
    // Declutched below walking pace the car is being braked to a stop, and stays there until it moves off
    // (the moving-off mode): its speed no more uncertain than it was.
    x.v = std::max(x.v + std::min(habits.coast_accel, 0.0) * dt, 0.0);
    x.a = 0.0;
    x.pva = 0.0;
    return;
  }
  const auto [mean, sd] = acceleration(mode, habits);
  const double tau = habits.accel_time;
  // The integrated Ornstein-Uhlenbeck acceleration over dt (exact discretisation).
  const double r = dt / tau;
  const double phi = std::exp(-r);
  const double g = tau * (1.0 - phi);
  x.v += mean * dt + g * (x.a - mean);
  x.a = mean + phi * (x.a - mean);
  const double pvv = x.pvv + 2.0 * g * x.pva + g * g * x.paa;
  const double pva = phi * (x.pva + g * x.paa);
  const double paa = phi * phi * x.paa;
  const double s2 = sd * sd;
  x.pvv = pvv + s2 * tau * tau * std::max(2.0 * r - 3.0 + 4.0 * phi - phi * phi, 0.0);
  x.pva = pva + s2 * tau * (1.0 - phi) * (1.0 - phi);
  x.paa = paa + s2 * (1.0 - phi * phi);
  if (x.v < 0.0) {  // a car does not roll backwards: it stands
    x.v = 0.0;
    x.a = std::max(x.a, 0.0);
  }
}

double ModeFilter::update_gps(SpeedTrack& x, double gps) const noexcept {
  const double r = ladder_.sigma_speed * ladder_.sigma_speed;
  return robust_update(x, gps, r, 0.0, 1.0, 1.0);
}

double ModeFilter::update_freq(SpeedTrack& x, int mode, double freq, double weight,
                               const DrivingHabits& habits) const noexcept {
  const double high = std::max({1.5 * habits.freq_max, 1.2 * freq, 1.0});
  if (mode == launch()) {
    // The driver raises the revs above idle not to stall the engine as the clutch takes up.
    const bool known = std::isfinite(habits.idle);
    const double lo = known ? habits.idle + 2.0 * habits.idle_sd : 0.0;
    const double hi = known ? kLaunchRevs * habits.idle : high;
    const double p = freq >= lo && freq <= hi ? 1.0 / (hi - lo) : 0.0;
    // A slipping clutch turns the engine faster than first gear would at this speed; once the car has
    // caught up, the clutch has bitten.
    const double caught = ladder_.theta[1] * freq;
    const double sd = std::sqrt(x.pvv + kSlip * kSlip * caught * caught + 0.01);
    const double slipping = 0.5 * std::erfc(-(caught - x.v) / (sd * std::sqrt(2.0)));
    // The estimate is held inside that bound (the constrained filter's projection), and is no surer than
    // the bound alone makes it: a speed anywhere from standing to caught up (a uniform's variance).
    if (x.v > caught) x.v = caught, x.pvv = std::min(x.pvv, caught * caught);
    x.pvv = std::max(x.pvv, caught * caught / 12.0);
    return weight * (std::log(std::max(p, kFreqOutlier / high)) + std::log(std::max(slipping, 1e-12)));
  }
  if (mode == 0) {
    double p = 1.0 / high;
    if (std::isfinite(habits.idle)) {
      const double share = x.v < kStanding ? kIdleShareStanding : kIdleShareRolling;
      const double y = freq - habits.idle;
      p = share * std::exp(log_normal(y, habits.idle_sd * habits.idle_sd)) + (1.0 - share) / high;
    }
    return weight * std::log(p);
  }
  const double theta = ladder_.theta[mode];
  const double z = theta * freq;
  const double se = ladder_.theta_se[mode] * freq;
  const double r = theta * theta * ladder_.sigma_freq * ladder_.sigma_freq + se * se + kSlip * kSlip * z * z;
  // The reading in speed units; its density in frequency units carries the Jacobian theta.
  const double log_l = robust_update(x, z, r, kFreqOutlier, theta * high, weight);
  // How usual these revs are in this gear for this driver, against his most usual: no one drives on in
  // fifth at idle revs, and a gear is seldom run far outside the band a driver keeps it in.
  double habit = 0.0;
  if (std::isfinite(habits.gear_revs_mean[mode])) {
    const double zr = (std::log(freq) - habits.gear_revs_mean[mode]) / habits.gear_revs_sd[mode];
    habit = -0.5 * zr * zr;
  }
  // Revs at idle in a gear above first: as often as this driver lugs a gear, against the idle's own share
  // declutched.
  if (mode > 1 && std::isfinite(habits.idle) && freq < habits.idle + 2.0 * habits.idle_sd)
    habit += std::log(habits.lugging);
  return log_l + weight * (std::log(theta) + habit);
}

void ModeFilter::step(double dt, double gps, double freq, const DrivingHabits& habits,
                      double evidence) noexcept {
  dt = std::max(dt, 0.0);
  const int n = modes();
  transition_matrix(dt, habits);
  // Generalised pseudo-Bayes of order 2: every pair (mode i before, mode j now) is predicted and updated on
  // its own, and the pairs into j are merged by their first two moments only after the readings have
  // weighed them. A merge before the update (the IMM's) would give a mode that many hypotheses flow into one
  // broad track, whose every reading then counts against it.
  std::array<SpeedTrack, kMaxModes> next{};
  ModeArray weight{};
  std::array<SpeedTrack, kMaxModes> post{};
  ModeArray log_w{};
  double best = -INFINITY;
  for (int j = 0; j < n; ++j) {
    // A change of mode ends what the pedals did: the speed carries over, the acceleration is drawn anew
    // from the new mode's own distribution.
    const Acceleration fresh = acceleration(j, habits);
    double top = -INFINITY;
    for (int i = 0; i < n; ++i) {
      const double p = trans_[i][j] * prob_[i];
      log_w[i] = -INFINITY;
      if (!(p > kMinProb * kMinProb)) continue;
      const SpeedTrack& from = track_[i];
      SpeedTrack x = i == j ? from : SpeedTrack{from.v, fresh.mean, from.pvv, 0.0, fresh.sd * fresh.sd};
      predict(x, j, dt, habits);
      double l = 0.0;
      if (std::isfinite(gps)) l += update_gps(x, gps);
      if (std::isfinite(freq) && freq > 0.0 && evidence > 0.0) l += update_freq(x, j, freq, evidence, habits);
      if (!std::isfinite(l)) continue;
      post[i] = x;
      log_w[i] = std::log(p) + l;
      top = std::max(top, log_w[i]);
    }
    if (!std::isfinite(top)) {  // nothing flows into j
      weight[j] = -INFINITY;
      next[j] = track_[j];
      continue;
    }
    double total = 0.0;
    SpeedTrack m{0.0, 0.0, 0.0, 0.0, 0.0};
    for (int i = 0; i < n; ++i) {
      if (!std::isfinite(log_w[i])) continue;
      const double w = std::exp(log_w[i] - top);
      total += w;
      m.v += w * post[i].v;
      m.a += w * post[i].a;
    }
    m.v /= total;
    m.a /= total;
    for (int i = 0; i < n; ++i) {
      if (!std::isfinite(log_w[i])) continue;
      const double w = std::exp(log_w[i] - top) / total;
      const double dv = post[i].v - m.v, da = post[i].a - m.a;
      m.pvv += w * (post[i].pvv + dv * dv);
      m.pva += w * (post[i].pva + dv * da);
      m.paa += w * (post[i].paa + da * da);
    }
    next[j] = m;
    weight[j] = top + std::log(total);
    best = std::max(best, weight[j]);
  }
  double total = 0.0;
  ModeArray prob{};
  for (int j = 0; j < n; ++j) {
    prob[j] = std::isfinite(best) && std::isfinite(weight[j]) ? std::exp(weight[j] - best) : 0.0;
    total += prob[j];
  }
  if (!(total > 0.0) || !std::isfinite(total)) {  // nothing explains the readings: keep the prior
    for (int j = 0; j < n; ++j) {
      prob[j] = 0.0;
      for (int i = 0; i < n; ++i)
        prob[j] += trans_[i][j] * prob_[i];
    }
    total = 1.0;
  }
  for (int j = 0; j < n; ++j)
    prob_[j] = std::max(prob[j] / total, kMinProb);
  track_ = next;
}

int ModeFilter::most_probable() const noexcept {
  int best = 0;
  for (int m = 1; m < modes(); ++m)
    if (prob_[m] > prob_[best]) best = m;
  return best;
}

double ModeFilter::mean_speed() const noexcept {
  double v = 0.0, total = 0.0;
  for (int m = 0; m < modes(); ++m)
    v += prob_[m] * track_[m].v, total += prob_[m];
  return total > 0.0 ? std::max(v / total, 0.0) : 0.0;
}

double ModeFilter::speed_spread(double about) const noexcept {
  double s = 0.0, total = 0.0;
  for (int m = 0; m < modes(); ++m) {
    const double d = track_[m].v - about;
    s += prob_[m] * (std::max(track_[m].pvv, 0.0) + d * d), total += prob_[m];
  }
  return total > 0.0 ? std::sqrt(s / total) : 0.0;
}

}  // namespace gearpulse
