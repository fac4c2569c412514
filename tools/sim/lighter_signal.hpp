#pragma once
// Synthetic cigarette-lighter voltage recordings: the engine-related ripple following a frequency
// trajectory f(t), with its 2nd and 3rd harmonics, a half-order component, ignition spikes at the firing
// rate, a fixed interfering tone (fan, pump), a supply level, and white noise at a given SNR (fundamental
// power over noise power inside the noise band, 50-200 Hz by default). Seeded and reproducible.
#include <cstdint>
#include <functional>
#include <limits>
#include <random>
#include <span>
#include <string>
#include <vector>

namespace gearpulse::sim {

// Engine-related frequency (Hz) at time t (s); NaN (or <= 0) means engine off: no engine component.
using FrequencyTrajectory = std::function<double(double)>;

struct LighterSignalConfig {
  double sample_rate_hz = 48000.0;
  double amplitude = 0.01;  // fundamental amplitude (full scale 1.0)
  double harmonic2 = 0.5;   // amplitudes relative to the fundamental
  double harmonic3 = 0.3;
  double half_order = 0.3;
  double spike_amplitude = 2.0;  // ignition spike peak relative to the fundamental amplitude
  double spike_decay_s = 2e-4;
  double spike_per_cycle = 1.0;  // spikes per fundamental period (firing rate / f)
  double tone_hz = std::numeric_limits<double>::quiet_NaN();  // fixed interfering tone, NaN = none
  double tone_amplitude = 0.0;                                // relative to the fundamental amplitude
  double dc = 0.0;                                            // supply level seen by the sound card
  double snr_db = 10.0;  // fundamental power / noise power inside [noise_lo_hz, noise_hi_hz]
  double noise_lo_hz = 50.0;
  double noise_hi_hz = 200.0;
  double clip = std::numeric_limits<double>::infinity();  // symmetric clipping level
  std::uint64_t seed = 1;
};

class LighterSignal {
 public:
  LighterSignal(const LighterSignalConfig& config, FrequencyTrajectory trajectory);
  // Writes the next out.size() samples (continuing phase and time from the previous call).
  void generate(std::span<float> out);
  [[nodiscard]] double time() const noexcept { return static_cast<double>(n_) / config_.sample_rate_hz; }
  [[nodiscard]] double noise_rms() const noexcept { return noise_rms_; }

 private:
  LighterSignalConfig config_;
  FrequencyTrajectory trajectory_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> gauss_{0.0, 1.0};
  double noise_rms_ = 0.0;
  double phase_ = 0.0;        // cycles of the fundamental
  double spike_phase_ = 0.0;  // cycles of the firing rate
  double spike_env_ = 0.0;
  double tone_phase_ = 0.0;
  std::uint64_t n_ = 0;
};

// Whole recording of `duration_s` seconds.
[[nodiscard]] std::vector<float> make_lighter_signal(const LighterSignalConfig& config,
                                                     const FrequencyTrajectory& trajectory,
                                                     double duration_s);

// Trajectory from samples of f at `rate_hz` (linear interpolation; NaN samples = engine off).
[[nodiscard]] FrequencyTrajectory trajectory_from_samples(std::vector<double> freq, double rate_hz);

// Writes a trajectory's samples at `rate_hz` up to `duration_s` (and two samples more): values held, ramps
// (linear, or a raised cosine when smooth) and single samples; whatever would run past the end is dropped.
// The drive-like trajectories below are written through it.
class TrajectoryWriter {
 public:
  TrajectoryWriter(double duration_s, double rate_hz);
  [[nodiscard]] bool full() const noexcept { return f_.size() >= steps_; }
  [[nodiscard]] double rate() const noexcept { return rate_; }
  [[nodiscard]] bool empty() const noexcept { return f_.empty(); }
  [[nodiscard]] double last() const { return f_.back(); }
  void push(double value);
  void hold(double value, double seconds);
  void ramp(double from, double to, double seconds, bool smooth);
  [[nodiscard]] FrequencyTrajectory finish() &&;

 private:
  double rate_;
  std::size_t steps_;
  std::vector<double> f_;
};

// A drive of `duration_s` seconds: idle below the band, accelerations through the gears with shifts
// (frequency drops of 30-40 % within 0.3 s), cruising, decelerations and stops with the engine off.
// Seeded; returns a trajectory sampled at 100 Hz.
[[nodiscard]] FrequencyTrajectory drive_trajectory(double duration_s, std::uint64_t seed);

// Minimal RIFF/WAVE writer (16-bit PCM, interleaved). False and `error` set on failure.
bool write_wav_pcm16(const std::string& path, std::span<const float> interleaved, int channels,
                     int sample_rate, std::string& error);

}  // namespace gearpulse::sim
