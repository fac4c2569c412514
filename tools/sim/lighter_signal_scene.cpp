#include "tools/sim/lighter_signal_scene.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <utility>

namespace gearpulse::sim {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;
// Time constant of the slope behind the load (s), and of the load's own slow wander (s) and its spread.
constexpr double kSlopeS = 0.3;
constexpr double kLoadWanderS = 3.0;
constexpr double kLoadWander = 0.2;
constexpr double kPumpWobble = 0.01;  // relative, over about 7 s
// The run-up: 3 s at 970 rpm, the ramp to 4,820 rpm, 2 s there (firing frequencies of a four-cylinder); the
// 2nd harmonic's resonance at 160 Hz, the 2nd harmonic of the engine at 2,400 rpm.
constexpr double kRunUpIdleS = 3.0, kRunUpHoldS = 2.0, kRunUpFromHz = 970.0 / 30.0,
                 kRunUpToHz = 4820.0 / 30.0;
constexpr double kRunUpSecondHz = 160.0;

bool engine_on(double f) {
  return std::isfinite(f) && f > 0.0;
}

double wrap(double phase) {
  return phase > 1024.0 ? phase - 1024.0 : phase;  // a multiple of 2 keeps half orders continuous
}

}  // namespace

LighterSceneConfig scene_for_seed(std::uint64_t seed, double snr_db, double sample_rate_hz) {
  std::mt19937_64 rng(seed * 7919 + 17);
  const auto u = [&rng](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  LighterSceneConfig c;
  c.sample_rate_hz = sample_rate_hz;
  c.snr_db = snr_db;
  c.seed = seed;
  c.half_order = u(0.1, 0.6);
  c.order_1_5 = u(0.05, 0.4);
  c.harmonic2 = u(0.6, 1.6);
  c.harmonic3 = u(0.1, 0.5);
  c.load_swing = u(0.3, 0.7);
  c.spike_amplitude = u(0.5, 4.0);
  c.alternator_ratio = u(2.5, 3.0);
  c.alternator = u(0.1, 0.6);
  c.body_hz = u(20.0, 40.0);
  c.body_q = u(3.0, 10.0);
  c.body = u(2.0, 6.0);
  c.fan_hz = u(60.0, 190.0);
  c.fan = u(0.3, 1.5);
  c.pump_hz = u(90.0, 190.0);
  c.pump = u(0.1, 0.6);
  c.mains_hz = u(0.0, 1.0) < 0.5 ? 50.0 : 60.0;
  c.mains = u(0.0, 0.8);
  c.agc_s = u(0.5, 3.0);
  c.clip = u(0.15, 0.4);
  return c;
}

LighterScene::LighterScene(const LighterSceneConfig& config, FrequencyTrajectory trajectory)
    : config_(config), trajectory_(std::move(trajectory)), rng_(config.seed) {
  const double fs = config_.sample_rate_hz;
  if (!(fs > 0) || !(config_.noise_hi_hz > config_.noise_lo_hz) || config_.cylinders <= 0 ||
      !(config_.body_q > 0) || !(config_.body_hz > 0 && config_.body_hz < 0.5 * fs))
    throw std::invalid_argument("LighterScene: bad sample rate, noise band, cylinders or resonance");
  const double a2 = config_.amplitude * config_.amplitude / 2.0;  // fundamental power
  if (std::isfinite(config_.snr_db))
    noise_rms_ = std::sqrt(a2 / std::pow(10.0, config_.snr_db / 10.0) * (fs / 2.0) /
                           (config_.noise_hi_hz - config_.noise_lo_hz));
  // Two-pole resonator y = a1 y1 - a2 y2 + g x; its output variance for unit white input is
  // (1 + r^2) / ((1 - r^2) ((1 + r^2)^2 - a1^2)).
  const double r = std::exp(-std::numbers::pi * config_.body_hz / config_.body_q / fs);
  body_a1_ = 2.0 * r * std::cos(kTwoPi * config_.body_hz / fs);
  body_a2_ = r * r;
  const double var =
      (1.0 + body_a2_) / ((1.0 - body_a2_) * ((1.0 + body_a2_) * (1.0 + body_a2_) - body_a1_ * body_a1_));
  body_gain_ = config_.body * std::sqrt(a2) / std::sqrt(var);
  envelope_ = config_.amplitude;
  gain_ = config_.agc_s > 0.0 ? config_.agc_level / envelope_ : config_.fixed_gain;
  fan_running_ = std::uniform_real_distribution<double>(0.0, 1.0)(rng_) < 0.5;
  fan_next_s_ = std::exponential_distribution<double>(1.0 / config_.fan_on_s)(rng_);
}

void LighterScene::generate(std::span<float> out) {
  const LighterSceneConfig& c = config_;
  const double fs = c.sample_rate_hz;
  const double a = c.amplitude;
  const double spike_decay = std::exp(-1.0 / (fs * c.spike_decay_s));
  const double slope_keep = std::exp(-1.0 / (fs * kSlopeS));
  const double wander_keep = std::exp(-1.0 / (fs * kLoadWanderS));
  const double wander_step = kLoadWander * std::sqrt(1.0 - wander_keep * wander_keep);
  const double agc_keep = c.agc_s > 0.0 ? std::exp(-1.0 / (fs * c.agc_s)) : 1.0;
  for (float& sample : out) {
    const double t = static_cast<double>(n_) / fs;
    const double f = trajectory_ ? trajectory_(t) : std::numeric_limits<double>::quiet_NaN();
    load_drift_ = wander_keep * load_drift_ + wander_step * gauss_(rng_);
    double v = 0.0;
    if (engine_on(f)) {
      const double d = engine_on(last_f_) ? (f - last_f_) * fs : 0.0;
      slope_ = slope_keep * slope_ + (1.0 - slope_keep) * d;
      load_ = std::clamp(0.5 + 0.5 * slope_ / c.load_slew_hz_per_s + load_drift_, 0.0, 1.0);
      const double swing = c.load_swing * (2.0 * load_ - 1.0);
      const double p = kTwoPi * phase_;
      double second = c.harmonic2 * (1.0 - swing);
      if (c.harmonic2_peak_hz > 0.0) {
        const double x = 2.0 * f / c.harmonic2_peak_hz;
        const double detune = c.harmonic2_peak_q * (x - 1.0 / x);
        second *= 1.0 + (c.harmonic2_peak - 1.0) / (1.0 + detune * detune);
      }
      v += a * ((1.0 + swing) * std::sin(p) + second * std::sin(2.0 * p + 0.7) +
                c.harmonic3 * std::sin(3.0 * p + 1.9) + c.half_order * std::sin(0.5 * p + 0.3) +
                c.order_1_5 * std::sin(1.5 * p + 2.3) + c.harmonic4 * std::sin(4.0 * p + 2.9));
      v += a * c.alternator * std::sin(kTwoPi * alt_phase_);
      phase_ = wrap(phase_ + f / fs);
      alt_phase_ = wrap(alt_phase_ + c.alternator_ratio * 2.0 * f / c.cylinders / fs);
      const double before = spike_phase_;
      spike_phase_ = wrap(spike_phase_ + f / fs);
      if (std::floor(spike_phase_) != std::floor(before)) spike_env_ += c.spike_amplitude * a;
    }
    last_f_ = f;
    v += spike_env_;
    spike_env_ *= spike_decay;
    // Body resonance: noise through a resonator, whatever the revs.
    const double body = body_a1_ * body_y1_ - body_a2_ * body_y2_ + body_gain_ * gauss_(rng_);
    body_y2_ = body_y1_;
    body_y1_ = body;
    v += body;
    // Fan (a PWM drive: its line and 2nd harmonic), switched on and off; pump with a slow wobble.
    if (t >= fan_next_s_) {
      fan_running_ = !fan_running_;
      fan_next_s_ = t + std::exponential_distribution<double>(1.0 / c.fan_on_s)(rng_);
    }
    if (fan_running_)
      v += a * c.fan * (std::sin(kTwoPi * fan_phase_) + 0.3 * std::sin(2.0 * kTwoPi * fan_phase_ + 0.4));
    fan_phase_ = std::fmod(fan_phase_ + c.fan_hz / fs, 1.0);
    v += a * c.pump * std::sin(kTwoPi * pump_phase_);
    pump_phase_ = std::fmod(pump_phase_ + c.pump_hz * (1.0 + kPumpWobble * std::sin(0.9 * t)) / fs, 1.0);
    const double m = kTwoPi * mains_phase_;
    v += a * c.mains * (0.5 * std::sin(m) + std::sin(2.0 * m + 1.1) + 0.4 * std::sin(3.0 * m + 0.2));
    mains_phase_ = std::fmod(mains_phase_ + c.mains_hz / fs, 1.0);
    if (noise_rms_ > 0.0) v += noise_rms_ * gauss_(rng_);
    // Automatic gain, then the card's clipping.
    if (c.agc_s > 0.0) {
      envelope_ = agc_keep * envelope_ + (1.0 - agc_keep) * std::abs(v);
      gain_ = c.agc_level / std::max(envelope_, 1e-9);
      v *= gain_;
    } else {
      v *= c.fixed_gain;
    }
    sample = static_cast<float>(std::clamp(v, -c.clip, c.clip));
    ++n_;
  }
}

std::vector<float> make_lighter_scene(const LighterSceneConfig& config, const FrequencyTrajectory& trajectory,
                                      double duration_s) {
  std::vector<float> out(
      static_cast<std::size_t>(std::max(0.0, std::round(duration_s * config.sample_rate_hz))));
  LighterScene scene(config, trajectory);
  scene.generate(out);
  return out;
}

namespace {

// The automatic gain's fixed stand-in: the envelope is a running mean of |v|, so a fixed gain of level /
// mean |v| holds its mean.
void switch_off_agc(LighterSceneConfig& config, const FrequencyTrajectory& trajectory, double duration_s) {
  LighterSceneConfig raw = config;
  raw.agc_s = 0.0;
  raw.fixed_gain = 1.0;
  raw.clip = std::numeric_limits<double>::infinity();
  const std::vector<float> x = make_lighter_scene(raw, trajectory, duration_s);
  double sum = 0.0;
  for (const float v : x)
    sum += std::abs(static_cast<double>(v));
  config.fixed_gain =
      x.empty() || !(sum > 0.0) ? 1.0 : config.agc_level * static_cast<double>(x.size()) / sum;
  config.agc_s = 0.0;
}

// Short names for the signatures of the table's switch-offs.
using Config = LighterSceneConfig;
using Trajectory = FrequencyTrajectory;

}  // namespace

// Names as bench_tracker's --scene-without takes them; what each is, where not plain, above it.
constexpr std::array<SceneComponent, 11> kSceneComponents = {{
    // The automatic gain.
    {"agc", &switch_off_agc},
    {"clipping",
     [](Config& c, const Trajectory&, double) { c.clip = std::numeric_limits<double>::infinity(); }},
    // The body/cabin resonance.
    {"resonance", [](Config& c, const Trajectory&, double) { c.body = 0.0; }},
    // The ignition spikes.
    {"spikes", [](Config& c, const Trajectory&, double) { c.spike_amplitude = 0.0; }},
    {"fan", [](Config& c, const Trajectory&, double) { c.fan = 0.0; }},
    {"pump", [](Config& c, const Trajectory&, double) { c.pump = 0.0; }},
    {"mains", [](Config& c, const Trajectory&, double) { c.mains = 0.0; }},
    // The alternator's whine.
    {"whine", [](Config& c, const Trajectory&, double) { c.alternator = 0.0; }},
    // The half orders: 0.5 f and 1.5 f.
    {"half",
     [](Config& c, const Trajectory&, double) {
       c.half_order = 0.0;
       c.order_1_5 = 0.0;
     }},
    // The load's swap of energy between f and 2 f.
    {"swap",
     [](Config& c, const Trajectory&, double) {
       // A run-up's resonance was set for the swing at full load: the 2nd harmonic keeps its peak level.
       if (c.harmonic2_peak_hz > 0.0) c.harmonic2_peak *= (1.0 - c.load_swing) / (1.0 + c.load_swing);
       c.load_swing = 0.0;
     }},
    // The 3rd harmonic.
    {"third", [](Config& c, const Trajectory&, double) { c.harmonic3 = 0.0; }},
}};
// (A lambda's function pointer is never null, and comparing one is no constant expression in every build.)
static_assert(std::ranges::none_of(kSceneComponents, [](const SceneComponent& c) { return c.name.empty(); }),
              "an entry of kSceneComponents left without a name");

bool scene_without(LighterSceneConfig& config, std::string_view component,
                   const FrequencyTrajectory& trajectory, double duration_s) {
  const auto found = std::ranges::find(kSceneComponents, component, &SceneComponent::name);
  if (found == kSceneComponents.end()) return false;
  found->switch_off(config, trajectory, duration_s);
  return true;
}

FrequencyTrajectory run_up_trajectory(double ramp_s) {
  return [ramp_s](double t) {
    if (!(t >= 0.0) || t > run_up_duration(ramp_s)) return std::numeric_limits<double>::quiet_NaN();
    return kRunUpFromHz + (kRunUpToHz - kRunUpFromHz) * std::clamp((t - kRunUpIdleS) / ramp_s, 0.0, 1.0);
  };
}

double run_up_duration(double ramp_s) {
  return kRunUpIdleS + ramp_s + kRunUpHoldS;
}

LighterSceneConfig run_up_scene_for_seed(std::uint64_t seed, double snr_db, double ramp_s,
                                         double second_over) {
  LighterSceneConfig c = scene_for_seed(seed, snr_db);
  c.load_slew_hz_per_s = (kRunUpToHz - kRunUpFromHz) / ramp_s;
  c.harmonic2_peak_hz = kRunUpSecondHz;
  // At the peak and full load: harmonic2 (1 - swing) times the gain over the fundamental's 1 + swing.
  c.harmonic2_peak = second_over * (1.0 + c.load_swing) / (c.harmonic2 * (1.0 - c.load_swing));
  return c;
}

LighterSceneConfig no_third_scene_for_seed(std::uint64_t seed, double snr_db, bool with_half) {
  LighterSceneConfig c = scene_for_seed(seed, snr_db);
  std::mt19937_64 rng(seed * 104729 + 3);  // its own stream: scene_for_seed()'s draws are kept
  c.harmonic3 = 0.0;
  c.harmonic4 = std::uniform_real_distribution<double>(0.2, 0.6)(rng);
  if (!with_half) c.half_order = c.order_1_5 = 0.0;
  return c;
}

FrequencyTrajectory launch_drive_trajectory(double duration_s, std::uint64_t seed) {
  constexpr double kRate = 100.0;
  std::mt19937_64 rng(seed);
  const auto u = [&rng](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  TrajectoryWriter f(duration_s, kRate);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double idle = u(25.0, 30.0);  // 750-900 rpm
  f.hold(nan, 1.0);
  while (!f.full()) {
    f.hold(idle, u(1.5, 3.0));
    // Launch: up to 1,500 rpm/s (50 Hz/s) in first gear, slower in each gear after.
    double cur = idle;
    double rate = u(35.0, 50.0);
    const int gears = static_cast<int>(u(2.0, 5.99));
    for (int g = 0; g < gears && !f.full(); ++g) {
      const double top = u(110.0, 195.0);
      f.ramp(cur, top, (top - cur) / rate, false);
      cur = top;
      rate *= u(0.45, 0.7);
      if (g + 1 < gears) {
        const double next = cur * u(0.6, 0.72);
        f.ramp(cur, next, u(0.25, 0.5), true);
        cur = next;
      }
    }
    const double cruise_s = u(3.0, 10.0);
    const double wobble = u(1.0, 4.0);
    const double base = cur;
    for (int i = 0; i < static_cast<int>(cruise_s * kRate) && !f.full(); ++i)
      f.push(base + wobble * std::sin(std::numbers::pi * i / kRate / 2.0));
    cur = f.last();
    if (u(0.0, 1.0) < 0.5) {  // a blip on a downshift
      const double peak = std::min(200.0, cur * u(1.2, 1.4));
      f.ramp(cur, peak, 0.3, true);
      f.ramp(peak, cur * 1.1, 0.4, true);
      cur *= 1.1;
    }
    // Engine braking back to idle.
    f.ramp(cur, 35.0, (cur - 35.0) / u(8.0, 20.0), false);
    f.ramp(35.0, idle, 0.6, true);
    f.hold(idle, u(1.0, 3.0));
    if (u(0.0, 1.0) < 0.5) f.hold(nan, u(1.5, 3.0));  // engine off
  }
  return std::move(f).finish();
}

}  // namespace gearpulse::sim
