#pragma once
// Files of a simulated drive, as the demo, the end-to-end test and the measurements feed them to the
// real chain: raw and WAV lighter voltage, the truth, the 1 Hz generic sample CSV, and the outage spec.
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace gearpulse::sim {

// A GPS outage of the simulated drive: no fix in [start, start + length).
struct Outage {
  double start = 0.0;   // s from the drive's start
  double length = 0.0;  // s; 0 = no outage

  [[nodiscard]] bool contains(double t) const noexcept { return t >= start && t < start + length; }
};

// Parses "START:LEN" (seconds, both >= 0); throws std::invalid_argument naming the text.
[[nodiscard]] Outage parse_outage(std::string_view text);

// One row of truth.csv.
struct TruthRow {
  double t = 0.0;      // s
  double speed = 0.0;  // m/s
  double freq = 0.0;   // Hz of the engine component
  int gear = 0;        // 0 = none (clutch out, standstill)
};

// One row of samples.csv (the generic format of docs/interfaces.md); NaN cells are written empty.
struct SampleRow {
  double t = 0.0;
  double speed = 0.0;
  double freq = 0.0;
};

// Converts volts-like samples in [-1, 1] to S16, clipping (a real sound card clips too).
[[nodiscard]] std::vector<std::int16_t> to_s16(std::span<const float> signal);

// Each throws std::runtime_error naming the path when it cannot be written.
void write_raw_s16(const std::string& path, std::span<const std::int16_t> pcm);
void write_wav_s16(const std::string& path, std::span<const std::int16_t> pcm, int rate);
void write_truth_csv(const std::string& path, std::span<const TruthRow> rows);
void write_samples_csv(const std::string& path, std::span<const SampleRow> rows);
void write_lines(const std::string& path, std::span<const std::string> lines);

// Distance travelled, trapezoidal over the rows (m).
[[nodiscard]] double distance_m(std::span<const TruthRow> rows) noexcept;

}  // namespace gearpulse::sim
