#include "tools/sim/lighter_signal.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <numbers>
#include <stdexcept>
#include <utility>

namespace gearpulse::sim {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

bool engine_on(double f) {
  return std::isfinite(f) && f > 0.0;
}

}  // namespace

LighterSignal::LighterSignal(const LighterSignalConfig& config, FrequencyTrajectory trajectory)
    : config_(config), trajectory_(std::move(trajectory)), rng_(config.seed) {
  if (!(config_.sample_rate_hz > 0) || !(config_.noise_hi_hz > config_.noise_lo_hz))
    throw std::invalid_argument("LighterSignal: bad sample rate or noise band");
  // White noise of variance s2 puts s2 * (hi - lo) / (fs / 2) inside the band; the fundamental's
  // power is A^2 / 2.
  const double snr = std::pow(10.0, config_.snr_db / 10.0);
  const double in_band = config_.amplitude * config_.amplitude / 2.0 / snr;
  noise_rms_ =
      std::isfinite(config_.snr_db)
          ? std::sqrt(in_band * (config_.sample_rate_hz / 2.0) / (config_.noise_hi_hz - config_.noise_lo_hz))
          : 0.0;
}

void LighterSignal::generate(std::span<float> out) {
  const double fs = config_.sample_rate_hz;
  const double a = config_.amplitude;
  const double spike_decay = std::exp(-1.0 / (fs * config_.spike_decay_s));
  for (float& sample : out) {
    const double t = static_cast<double>(n_) / fs;
    const double f = trajectory_ ? trajectory_(t) : std::numeric_limits<double>::quiet_NaN();
    double v = config_.dc;
    if (engine_on(f)) {
      const double p = kTwoPi * phase_;
      v += a * (std::sin(p) + config_.harmonic2 * std::sin(2.0 * p + 0.7) +
                config_.harmonic3 * std::sin(3.0 * p + 1.9) + config_.half_order * std::sin(0.5 * p + 0.3));
      // Phase-continuous integration of f: the waveform never jumps when f does.
      phase_ += f / fs;
      const double before = spike_phase_;
      spike_phase_ += f * config_.spike_per_cycle / fs;
      if (std::floor(spike_phase_) != std::floor(before)) spike_env_ += config_.spike_amplitude * a;
      // Keep the phases small so precision does not degrade over long recordings.
      if (phase_ > 1024.0) phase_ -= 1024.0;  // a multiple of 2 keeps the half order continuous
      if (spike_phase_ > 1024.0) spike_phase_ -= 1024.0;
    }
    v += spike_env_;
    spike_env_ *= spike_decay;
    if (std::isfinite(config_.tone_hz) && config_.tone_amplitude != 0.0) {
      v += config_.tone_amplitude * a * std::sin(kTwoPi * tone_phase_);
      tone_phase_ += config_.tone_hz / fs;
      if (tone_phase_ > 1.0) tone_phase_ -= 1.0;
    }
    if (noise_rms_ > 0.0) v += noise_rms_ * gauss_(rng_);
    v = std::clamp(v, -config_.clip, config_.clip);
    sample = static_cast<float>(v);
    ++n_;
  }
}

std::vector<float> make_lighter_signal(const LighterSignalConfig& config,
                                       const FrequencyTrajectory& trajectory, double duration_s) {
  std::vector<float> out(
      static_cast<std::size_t>(std::max(0.0, std::round(duration_s * config.sample_rate_hz))));
  LighterSignal gen(config, trajectory);
  gen.generate(out);
  return out;
}

FrequencyTrajectory trajectory_from_samples(std::vector<double> freq, double rate_hz) {
  return [f = std::move(freq), rate_hz](double t) {
    const double x = t * rate_hz;
    if (f.empty() || !(x >= 0.0)) return std::numeric_limits<double>::quiet_NaN();
    const auto i = static_cast<std::size_t>(x);
    if (i + 1 >= f.size()) return i < f.size() ? f[i] : std::numeric_limits<double>::quiet_NaN();
    const double w = x - static_cast<double>(i);
    if (!std::isfinite(f[i]) || !std::isfinite(f[i + 1])) return w < 0.5 ? f[i] : f[i + 1];
    return f[i] + w * (f[i + 1] - f[i]);
  };
}

TrajectoryWriter::TrajectoryWriter(double duration_s, double rate_hz)
    : rate_(rate_hz), steps_(static_cast<std::size_t>(std::ceil(duration_s * rate_hz)) + 2) {
  f_.reserve(steps_);
}

void TrajectoryWriter::push(double value) {
  if (!full()) f_.push_back(value);
}

void TrajectoryWriter::hold(double value, double seconds) {
  for (int i = 0; i < static_cast<int>(seconds * rate_) && !full(); ++i)
    f_.push_back(value);
}

void TrajectoryWriter::ramp(double from, double to, double seconds, bool smooth) {
  const int n = std::max(1, static_cast<int>(seconds * rate_));
  for (int i = 1; i <= n && !full(); ++i) {
    double w = static_cast<double>(i) / n;
    if (smooth) w = 0.5 - 0.5 * std::cos(std::numbers::pi * w);
    f_.push_back(from + w * (to - from));
  }
}

FrequencyTrajectory TrajectoryWriter::finish() && {
  return trajectory_from_samples(std::move(f_), rate_);
}

FrequencyTrajectory drive_trajectory(double duration_s, std::uint64_t seed) {
  constexpr double kRate = 100.0;
  constexpr double kIdle = 40.0;  // below the 50-200 Hz band
  std::mt19937_64 rng(seed);
  const auto uniform = [&rng](double lo, double hi) {
    return std::uniform_real_distribution<double>(lo, hi)(rng);
  };
  TrajectoryWriter f(duration_s, kRate);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  f.hold(nan, 1.0);
  while (!f.full()) {
    f.hold(kIdle, 1.5);
    f.ramp(kIdle, 58.0, 0.8, true);  // clutch engages
    double cur = 58.0;
    const int gears = static_cast<int>(uniform(3.0, 5.99));
    for (int g = 0; g < gears && !f.full(); ++g) {
      const double top = uniform(120.0, 185.0);
      f.ramp(cur, top, (top - cur) / uniform(12.0, 30.0), false);
      cur = top;
      if (g + 1 < gears) {
        const double next = cur * uniform(0.6, 0.72);
        f.ramp(cur, next, 0.5, true);
        cur = next;
      }
    }
    // Cruise with a slow wobble.
    const double cruise_s = uniform(4.0, 10.0);
    const double wobble = uniform(1.0, 4.0);
    for (int i = 0; i < static_cast<int>(cruise_s * kRate) && !f.full(); ++i)
      f.push(cur + wobble * std::sin(std::numbers::pi * i / kRate / 2.0));
    cur = f.empty() ? cur : f.last();
    f.ramp(cur, 55.0, (cur - 55.0) / uniform(8.0, 20.0), false);
    f.ramp(55.0, kIdle, 0.6, true);
    f.hold(kIdle, 1.5);
    f.hold(nan, uniform(2.0, 3.5));  // engine off
  }
  return std::move(f).finish();
}

bool write_wav_pcm16(const std::string& path, std::span<const float> interleaved, int channels,
                     int sample_rate, std::string& error) {
  if (channels <= 0 || sample_rate <= 0) {
    error = path + ": bad channel count or sample rate";
    return false;
  }
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) {
    error = path + ": cannot open for writing";
    return false;
  }
  const auto u32 = [&out](std::uint32_t v) {
    const unsigned char b[4] = {static_cast<unsigned char>(v), static_cast<unsigned char>(v >> 8),
                                static_cast<unsigned char>(v >> 16), static_cast<unsigned char>(v >> 24)};
    out.write(reinterpret_cast<const char*>(b), 4);
  };
  const auto u16 = [&out](std::uint16_t v) {
    const unsigned char b[2] = {static_cast<unsigned char>(v), static_cast<unsigned char>(v >> 8)};
    out.write(reinterpret_cast<const char*>(b), 2);
  };
  const auto data_bytes = static_cast<std::uint32_t>(interleaved.size() * 2);
  out.write("RIFF", 4);
  u32(36 + data_bytes);
  out.write("WAVEfmt ", 8);
  u32(16);
  u16(1);  // PCM
  u16(static_cast<std::uint16_t>(channels));
  u32(static_cast<std::uint32_t>(sample_rate));
  u32(static_cast<std::uint32_t>(sample_rate * channels * 2));
  u16(static_cast<std::uint16_t>(channels * 2));
  u16(16);
  out.write("data", 4);
  u32(data_bytes);
  for (float x : interleaved) {
    const double v = std::clamp(static_cast<double>(x), -1.0, 1.0) * 32767.0;
    u16(static_cast<std::uint16_t>(static_cast<std::int16_t>(std::lround(v))));
  }
  out.flush();
  if (!out) {
    error = path + ": write failed";
    return false;
  }
  return true;
}

}  // namespace gearpulse::sim
