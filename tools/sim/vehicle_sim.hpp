#pragma once
// Seeded drive simulator: a manual gearbox (or a CVT) driven by a stochastic driver, producing the true
// speed and engine frequency at any time step, and noisy observations of them (GPS-like or OBD-like).
//
// Typical use:
//   sim::Vehicle car = sim::vehicle_preset("bmw-520i");
//   sim::DriveOptions drive_options;  // style, duration (s), dt (s), seed
//   sim::Drive drive = sim::simulate_drive(car, drive_options);
//   auto observed = sim::observe(drive, {});  // 1 Hz, sigma_v = 0.05 m/s, sigma_s = 0.2 Hz
//   std::vector<Sample> samples = sim::to_samples(observed);  // input of fit_gear_model / replay
// Audio synthesis uses drive.truth directly (DriveOptions::dt = 0.01 gives 100 Hz), or truth_at(drive, t).
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/sample.hpp"

namespace gearpulse::sim {

struct Vehicle {
  std::string name;
  std::vector<double> theta;   // m/s per Hz of the engine component, ascending; empty = CVT (no ladder)
  double cvt_theta_min = 0.0;  // CVT only: ratio range, m/s per Hz
  double cvt_theta_max = 0.0;
  double idle_freq = 13.3;       // Hz of the engine component at idle
  double max_freq = 100.0;       // Hz at the rev limiter
  double upshift_freq = 40.0;    // Hz, typical upshift point under normal acceleration
  double downshift_freq = 20.0;  // Hz, the driver shifts down below this
  double max_accel = 2.5;        // m/s^2 in first gear at full throttle

  [[nodiscard]] int gears() const noexcept { return static_cast<int>(theta.size()); }
  [[nodiscard]] bool is_cvt() const noexcept { return theta.empty(); }
};

// The paper's BMW 520i (Table 3 reference thetas, engine component ~3x crank frequency).
[[nodiscard]] Vehicle bmw_520i();
// All presets: "bmw-520i", "hatch-5" (Etios-like 5-speed), "close-6" (~1.2-1.3 steps), "wide-4" (~1.7+
// steps), "van-6" (wide low gears), "sport-7", "compact-4", "cvt".
[[nodiscard]] std::vector<Vehicle> vehicle_presets();
// Throws std::invalid_argument for an unknown name.
[[nodiscard]] Vehicle vehicle_preset(std::string_view name);
// A manual vehicle drawn at random, for checks beyond the presets: 4-7 gears, a progressive ladder (the
// steps shrink toward the top, as real gearboxes' do) from a first gear 3.0-5.2x as short as the top,
// the engine component a 0.5x-6x multiple of the crank frequency (a harmonic, an alternator's ripple),
// idle, rev limit, the driver's shift points and the car's pull drawn from plausible ranges. The same
// seed gives the same vehicle ("random-SEED").
[[nodiscard]] Vehicle random_vehicle(std::uint64_t seed);
// A wider family than random_vehicle's, for robustness beyond the ranges the design was tuned on: petrol
// cars of 3-9 gears, diesels and light vans (idle 600-850 rpm, limit 3800-4800), motorcycles (idle
// 1100-1500 rpm, limit 8500-12500, 5-6 close gears); irregular ladders (a crawler first, two close top
// gears, a tall overdrive; spread up to 8); the crank or a firing frequency of 1-8 cylinders (0.5x-4x).
// random_vehicle is left as it was. The same seed gives the same vehicle ("wide-family-SEED").
[[nodiscard]] Vehicle wide_vehicle(std::uint64_t seed);

enum class DrivingStyle { kMixed, kUrban, kHighway, kTrafficJam };
[[nodiscard]] std::string_view style_name(DrivingStyle style) noexcept;
// "mixed", "urban", "highway", "jam" (or "traffic-jam"); throws std::invalid_argument otherwise.
[[nodiscard]] DrivingStyle parse_style(std::string_view name);

enum class Clutch { kEngaged, kDisengaged, kSlipping };

struct TruthSample {
  double t = 0.0;      // s
  double speed = 0.0;  // m/s, true
  double freq = 0.0;   // Hz, true engine component frequency
  int gear = 0;        // 1..M while the clutch transmits (engaged or slipping), 0 = none/clutch out
  Clutch clutch = Clutch::kDisengaged;
};

struct DriveOptions {
  DrivingStyle style = DrivingStyle::kMixed;
  double duration = 2400.0;  // s
  double dt = 1.0;           // s between truth samples (the dynamics always run at 50 ms)
  std::uint64_t seed = 1;
  // A cold engine idles high and settles as it warms: the idle starts at (1 + cold_start) x idle_freq and
  // falls back with time constant warm_up (s). 0 = the engine is warm from the start.
  double cold_start = 0.0;
  double warm_up = 150.0;
  // Share of downshifts under braking that skip a gear (4 -> 2, 5 -> 3) where the lower gear's revs allow
  // it. 0 keeps every downshift to the next gear (and the drive of a seed as it was).
  double skip_downshift = 0.0;
};

struct Drive {
  Vehicle vehicle;
  DriveOptions options;
  std::vector<TruthSample> truth;  // truth[k].t = k * options.dt
};

// Same seed and style give the same drive whatever dt is (dt only changes the output grid).
[[nodiscard]] Drive simulate_drive(const Vehicle& vehicle, const DriveOptions& options);
// Truth at an arbitrary time (linear interpolation of speed and frequency; gear/clutch of the sample
// before t). t is clamped to the drive.
[[nodiscard]] TruthSample truth_at(const Drive& drive, double t);

struct ObservationOptions {
  double period = 1.0;        // s between observed rows
  double sigma_speed = 0.05;  // m/s, GPS Doppler noise (eq. (2)), a u-blox class receiver; clamped at 0
  double sigma_freq = 0.2;    // Hz, tracker noise (eq. (1))
  double freq_floor = 0.0;    // Hz; observed freq is NaN where the true freq is below (0 = off)
  double freq_ceiling = 0.0;  // Hz; NaN above (0 = off)
  // OBD-like logging: integer km/h speed, integer rpm (freq = rpm / 60 Hz is assumed), each value polled
  // once per refresh round at its own random instant (skew up to obd_skew s), rows repeat between polls.
  bool obd = false;
  double obd_refresh = 1.8;  // s per polling round
  double obd_skew = 1.0;     // s, max offset of each poll inside the round
  std::uint64_t seed = 2;
};

struct Observation {
  TruthSample truth;        // at the row time
  double speed = kMissing;  // m/s
  double freq = kMissing;   // Hz
};

[[nodiscard]] std::vector<Observation> observe(const Drive& drive, const ObservationOptions& options);
[[nodiscard]] std::vector<Sample> to_samples(const std::vector<Observation>& observations);

// Convenience: several drives of one vehicle concatenated in time (seeds seed, seed+1, ...), observed.
[[nodiscard]] std::vector<Observation> simulate_observations(const Vehicle& vehicle, DrivingStyle style,
                                                             double duration, int drives, std::uint64_t seed,
                                                             const ObservationOptions& observation = {});

}  // namespace gearpulse::sim
