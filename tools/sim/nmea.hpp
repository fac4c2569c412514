#pragma once
// NMEA 0183 log generator: a vehicle driving along a fixed heading at given speeds, one RMC and one GGA
// sentence per epoch (exactly two lines, so a player pacing 2 N lines a second replays N Hz epochs in
// real time: scripts/lib/harness.sh). Times print to the hundredth of a second (hhmmss.ss), as a 5 or
// 10 Hz receiver's do. Epochs whose speed is NaN are GPS outages: void RMC (status V) and GGA fix
// quality 0, position held.
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace gearpulse::sim {

struct NmeaEpoch {
  double t = 0.0;      // s since the start of the log (epochs 1 / N s apart for an N Hz receiver)
  double speed = 0.0;  // m/s over ground; NaN = no fix in this epoch
};

struct NmeaTrack {
  double lat0_deg = 55.7047;  // start position
  double lon0_deg = 13.1910;
  double heading_deg = 90.0;  // true course, degrees clockwise from north
  double altitude_m = 50.0;
  int year = 2026, month = 1, day = 15;     // UTC date of t = 0
  double utc_seconds_of_day = 12 * 3600.0;  // UTC time of day of t = 0 (the log must not cross midnight)
};

// "$" + body + "*" + two-digit checksum (XOR of the body's bytes) + "\r\n".
[[nodiscard]] std::string nmea_sentence(std::string_view body);

// Two sentences (RMC then GGA) per epoch, epochs in the given order; the position advances by the
// distance driven since the previous epoch at that epoch's speed (trapezoidal, outages hold position).
[[nodiscard]] std::vector<std::string> make_nmea_log(std::span<const NmeaEpoch> epochs,
                                                     const NmeaTrack& track);

// Writes the sentences of make_nmea_log to `path`; throws std::runtime_error naming the file on failure.
void write_nmea_log(const std::filesystem::path& path, std::span<const NmeaEpoch> epochs,
                    const NmeaTrack& track = {});

// Epochs at 1 Hz, t = 0 .. speeds.size()-1, speed[i] for epoch i (NaN = outage).
[[nodiscard]] std::vector<NmeaEpoch> epochs_at_1hz(std::span<const double> speeds);

}  // namespace gearpulse::sim
