#pragma once
// Synthetic lighter-voltage recordings closer to a real car than LighterSignal's: besides the engine's
// ripple they hold what a sound card on a lighter socket also picks up in a cabin.
//
// The engine's line f(t) (the tracked fundamental: the firing frequency, twice the crank rate on a
// four-cylinder) comes with
//   - half and one-and-a-half orders (0.5 f, 1.5 f) and a 3rd harmonic (or, in no_third_scene_for_seed()'s
//     scenes, a 4th in its place);
//   - energy that moves between f and 2 f with the load: under load (accelerating) the fundamental
//     leads, on the overrun (engine braking) and at light load the 2nd harmonic stands up to 12 dB over it;
//   - ignition spikes at the firing rate;
//   - alternator whine at a non-integer pulley order of the crank (2.5-3 x crank);
// and, independent of the revs,
//   - a strong body/cabin resonance (20-40 Hz, noise through a resonator);
//   - a PWM fan's line and its 2nd harmonic, switched on and off; a fuel pump's line with a slow wobble;
//   - mains hum from a charger (50 or 60 Hz and its 2nd and 3rd harmonics);
//   - white noise at a given SNR (fundamental power at mean load over the noise power in [noise_lo_hz,
//     noise_hi_hz]);
//   - a USB card's automatic gain (the level follows the signal's envelope over agc_s) and clipping.
// Seeded and reproducible; scene_for_seed() draws every level and frequency from its seed.
#include <array>
#include <cstdint>
#include <limits>
#include <random>
#include <span>
#include <string_view>
#include <vector>

#include "tools/sim/lighter_signal.hpp"

namespace gearpulse::sim {

struct LighterSceneConfig {
  double sample_rate_hz = 48000.0;
  double amplitude = 0.01;  // fundamental amplitude at mean load (0.5); the others are relative to it
  int cylinders = 4;        // crank rate = 2 f / cylinders
  double half_order = 0.3;  // 0.5 f
  double order_1_5 = 0.2;   // 1.5 f
  double harmonic2 = 1.0;   // 2 f at mean load
  double harmonic3 = 0.2;
  double harmonic4 = 0.0;  // 4 f (none in scene_for_seed()'s scenes; no_third_scene_for_seed()'s)
  // Load moves energy between f and 2 f: the fundamental's amplitude is (1 + swing (2 load - 1)), the 2nd
  // harmonic's harmonic2 (1 - swing (2 load - 1)).
  double load_swing = 0.6;
  double load_slew_hz_per_s = 30.0;  // engine acceleration that means full load (f's slope)
  // A resonance of the supply or the body that the 2nd harmonic passes through (at 2 f = harmonic2_peak_hz
  // its amplitude is harmonic2_peak times the above, with quality factor harmonic2_peak_q): the 2nd
  // harmonic rises through the fundamental at mid revs on a run-up. 0 Hz = none (scene_for_seed()'s).
  double harmonic2_peak_hz = 0.0;
  double harmonic2_peak = 1.0;
  double harmonic2_peak_q = 3.0;
  double spike_amplitude = 2.0;
  double spike_decay_s = 2e-4;
  double alternator_ratio = 2.7;  // alternator line at this multiple of the crank rate
  double alternator = 0.3;
  double body_hz = 30.0;  // body/cabin resonance
  double body_q = 6.0;
  double body = 3.0;  // its RMS over the fundamental's
  double fan_hz = 118.0;
  double fan = 0.7;
  double fan_on_s = 15.0;  // mean time on, and off
  double pump_hz = 153.0;
  double pump = 0.4;
  double mains_hz = 50.0;
  double mains = 0.5;
  double snr_db = 0.0;
  double noise_lo_hz = 50.0;
  double noise_hi_hz = 200.0;
  // Automatic gain: the output's envelope is held near agc_level (full scale 1.0) with this time
  // constant; 0 = no automatic gain (the output is the generator's scale times fixed_gain).
  double agc_s = 1.5;
  double agc_level = 0.1;
  double fixed_gain = 1.0;
  double clip = 0.25;  // symmetric clipping after the gain (the card's full scale is 1.0)
  std::uint64_t seed = 1;
};

// A component of the scene that scene_without() can switch off: its name (as bench_tracker's
// --scene-without takes it) and how it is switched off in a config.
struct SceneComponent {
  std::string_view name;
  void (*switch_off)(LighterSceneConfig& config, const FrequencyTrajectory& trajectory, double duration_s);
  // A component is found by its name (std::find over kSceneComponents).
  friend bool operator==(const SceneComponent& c, std::string_view name) noexcept { return c.name == name; }
};

// Every component scene_without() can switch off, the one list of their names (what each is: beside its
// entry in lighter_signal_scene.cpp).
extern const std::array<SceneComponent, 11> kSceneComponents;

// `config` with one component of kSceneComponents switched off: its level set to 0 (the noise and every
// other component's draw unchanged, the noise level being set by the fundamental). The automatic gain is
// replaced by the fixed gain that holds the recording's mean envelope at agc_level (hence `trajectory` and
// the duration). False for an unknown name.
[[nodiscard]] bool scene_without(LighterSceneConfig& config, std::string_view component,
                                 const FrequencyTrajectory& trajectory, double duration_s);

// A scene whose levels and frequencies are drawn from `seed` (within the ranges in the header comment),
// at the given SNR and sample rate.
[[nodiscard]] LighterSceneConfig scene_for_seed(std::uint64_t seed, double snr_db,
                                                double sample_rate_hz = 48000.0);

class LighterScene {
 public:
  LighterScene(const LighterSceneConfig& config, FrequencyTrajectory trajectory);
  // Writes the next out.size() samples.
  void generate(std::span<float> out);
  // Load in [0, 1] at the latest sample written (for tests: where 2 f leads).
  [[nodiscard]] double load() const noexcept { return load_; }

 private:
  LighterSceneConfig config_;
  FrequencyTrajectory trajectory_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> gauss_{0.0, 1.0};
  double noise_rms_ = 0.0;
  double body_a1_ = 0.0, body_a2_ = 0.0, body_gain_ = 0.0, body_y1_ = 0.0, body_y2_ = 0.0;
  double phase_ = 0.0, spike_phase_ = 0.0, spike_env_ = 0.0, alt_phase_ = 0.0;
  double fan_phase_ = 0.0, pump_phase_ = 0.0, mains_phase_ = 0.0;
  double last_f_ = std::numeric_limits<double>::quiet_NaN();
  double slope_ = 0.0, load_ = 0.5, load_drift_ = 0.0;
  bool fan_running_ = false;
  double fan_next_s_ = 0.0;
  double envelope_ = 0.0, gain_ = 1.0;
  std::uint64_t n_ = 0;
};

[[nodiscard]] std::vector<float> make_lighter_scene(const LighterSceneConfig& config,
                                                    const FrequencyTrajectory& trajectory, double duration_s);

// A run-up of a four-cylinder at full throttle, as its firing frequency: idle at 970 rpm (32.3 Hz) for
// 3 s, a steady ramp to 4,820 rpm (160.7 Hz) over ramp_s, then 2 s held there (run_up_duration()).
[[nodiscard]] FrequencyTrajectory run_up_trajectory(double ramp_s);
[[nodiscard]] double run_up_duration(double ramp_s);
// The scene of that run-up: scene_for_seed()'s levels and lines, the ramp's slope the full-load slope, and
// the 2nd harmonic through a resonance at 160 Hz (the engine at 2,400 rpm), where at full load it stands
// second_over times the fundamental's amplitude (a real cabin run-up's 2nd harmonic rose through the
// fundamental at mid revs).
[[nodiscard]] LighterSceneConfig run_up_scene_for_seed(std::uint64_t seed, double snr_db, double ramp_s,
                                                       double second_over = 2.0);

// A scene of an engine whose 3rd harmonic lies under the noise while its 2nd and 4th show (orders 1, 2 and
// 4 of the firing frequency; a real engine's orders need not follow a smooth ladder): scene_for_seed()'s
// levels and lines with the 3rd harmonic off, a 4th at 0.2-0.6 of the fundamental drawn from the seed, and
// the half orders (0.5 f, 1.5 f) kept or, with_half false, off.
[[nodiscard]] LighterSceneConfig no_third_scene_for_seed(std::uint64_t seed, double snr_db, bool with_half);

// A drive of a four-cylinder for the scene, as its firing frequency: idle at 750-900 rpm (25-30 Hz,
// below the 50-200 Hz band), launches at up to 1,500 rpm/s (50 Hz/s), shifts, cruising, engine braking
// back to idle, rev blips, and stops with the engine off. Seeded; sampled at 100 Hz.
[[nodiscard]] FrequencyTrajectory launch_drive_trajectory(double duration_s, std::uint64_t seed);

}  // namespace gearpulse::sim
