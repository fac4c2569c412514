// `gearpulse-devtools simulate`: writes a simulated drive as the real chain sees it: the lighter voltage a
// sound card would capture (raw S16 for the ALSA file plugin, WAV for `gearpulse track`), the NMEA log gpsd
// would read (no fix during the outage), the truth, and the 1 Hz sample CSV `gearpulse fit` reads.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "tools/gearpulse/commands.hpp"
#include "tools/sim/drive_files.hpp"
#include "tools/sim/lighter_signal.hpp"
#include "tools/sim/nmea.hpp"
#include "tools/sim/vehicle_sim.hpp"

namespace gearpulse::cli {
namespace {

struct SimulateOptions {
  std::string out;
  std::uint64_t seed = 1;
  double duration = 240.0;
  std::string outage;
  int rate = 48000;
  std::string vehicle = "bmw-520i";
  std::string style = "mixed";
  double snr_db = 10.0;
  double pulses_per_km = 2485.0;
  double stop_search = 120.0;
  bool no_audio = false;
  double idle_start = 8.0;
  double tone_hz = 0.0;
  int gps_lead = 8;
  int gps_hz = 1;  // fix sets a second in drive.nmea (1, 2, 5 or 10: what car-PC receivers report)
  double skip_downshift = 0.0;  // share of braking downshifts that skip a gear (DriveOptions::skip_downshift)
  double outage_at_skip = 0.0;  // s; > 0: an outage this long from the first braking skip-downshift
  bool skip_drive_on = false;   // that skip: one after which the car drives on in the lower gear
};

constexpr double kDriveStartUtc = 12 * 3600.0;  // UTC time of day of the drive's t = 0 in drive.nmea
constexpr double kTruthStep = 0.1;              // s between truth.csv rows
constexpr double kSignalStep = 0.01;            // s between the truth points the audio follows

// The lighter voltage of the drive: the engine component follows the true frequency, with its
// harmonics, half order, ignition spikes and noise from the project's signal generator.
std::vector<float> lighter_voltage(const sim::Drive& drive, int rate, double snr_db, double tone_hz,
                                   std::uint64_t seed) {
  std::vector<double> freq;
  freq.reserve(drive.truth.size());
  for (const sim::TruthSample& s : drive.truth)
    freq.push_back(s.freq);
  sim::LighterSignalConfig config;
  config.sample_rate_hz = rate;
  config.snr_db = snr_db;
  config.seed = seed;
  if (tone_hz > 0.0) {
    config.tone_hz = tone_hz;
    config.tone_amplitude = 0.5;
  }
  const double length = drive.truth.back().t;
  return sim::make_lighter_signal(
      config, sim::trajectory_from_samples(std::move(freq), 1.0 / drive.options.dt), length);
}

// Cuts the drive at its first standstill at or after `duration` (searching `search` s further), so the
// drive starts and ends at rest and its distance is complete whenever a reader stops counting.
std::size_t end_at_standstill(const sim::Drive& drive, double duration, double search) {
  const auto& truth = drive.truth;
  const double dt = drive.options.dt;
  const auto first = static_cast<std::size_t>(duration / dt);
  const auto last = std::min(truth.size(), static_cast<std::size_t>((duration + search) / dt));
  const auto hold = static_cast<std::size_t>(3.0 / dt);  // a real stop, not a zero crossing
  std::size_t still = 0;
  for (std::size_t i = first; i < last; ++i) {
    still = truth[i].speed < 0.05 ? still + 1 : 0;
    if (still >= hold) return i + 1;
  }
  return std::min(truth.size(), first + 1);
}

// The car idles at rest before it drives off, as a real drive starts: the receiver gets its first fixes
// and the capture settles before anything moves.
void prepend_idle(sim::Drive& drive, double seconds) {
  const auto n = static_cast<std::size_t>(std::lround(seconds / drive.options.dt));
  if (n == 0) return;
  sim::TruthSample idle = drive.truth.front();
  idle.speed = 0.0;
  idle.gear = 0;
  idle.clutch = sim::Clutch::kDisengaged;
  idle.freq = drive.vehicle.idle_freq;
  drive.truth.insert(drive.truth.begin(), n, idle);
  for (std::size_t k = 0; k < drive.truth.size(); ++k)
    drive.truth[k].t = static_cast<double>(k) * drive.options.dt;
}

// A downshift under braking that skips a gear (4 -> 2, 5 -> 3): when the clutch went out, for how long.
struct BrakingSkip {
  double clutch_out = -1.0;  // s; < 0: none
  double declutched = 0.0;   // s
  int from = 0, to = 0;
};

// The first braking skip-downshift whose clutch goes out at or after `after` s: the engaged gear, the
// clutch out for at most a shift's length, then a gear two or more lower, the car slowing by more than
// 1 m/s^2 over the second before (the simulator's driver skips only while braking). With `drive_on` the
// lower gear must then stay engaged for kDriveOn s (braking to a lower speed, not to a stop).
BrakingSkip first_braking_skip(const sim::Drive& drive, double after, bool drive_on) {
  constexpr double kDriveOn = 10.0;      // s in the lower gear: the car drives on, it does not stop
  constexpr double kBraking = 1.0;       // m/s^2, the simulator's braking threshold for a skip
  constexpr double kLongestShift = 1.6;  // s, the simulator's longest clutch-out (1.5 s) and a step
  const auto& truth = drive.truth;
  const auto second = static_cast<std::size_t>(std::lround(1.0 / drive.options.dt));
  std::size_t out = 0;
  int engaged = 0;
  for (std::size_t i = 1; i < truth.size(); ++i) {
    const int prev = truth[i - 1].gear, gear = truth[i].gear;
    if (prev > 0 && gear == 0) {
      engaged = prev;
      out = i;
    } else if (prev == 0 && gear > 0) {
      const double declutched = truth[i].t - truth[out].t;
      const bool skip = engaged > 0 && gear <= engaged - 2 && declutched <= kLongestShift;
      const bool braking = out >= second && truth[out - second].speed - truth[out].speed > kBraking * 1.0;
      std::size_t end = i;
      while (drive_on && end < truth.size() && truth[end].gear == gear &&
             truth[end].t - truth[i].t < kDriveOn)
        ++end;
      const bool drives_on = !drive_on || (end < truth.size() && truth[end].gear == gear);
      if (skip && braking && drives_on && truth[out].t >= after)
        return {truth[out].t, declutched, engaged, gear};
      engaged = 0;
    }
  }
  return {};
}

int count_shifts(const std::vector<sim::TruthRow>& rows, const sim::Outage& outage) {
  int shifts = 0;
  int last_gear = -1;
  for (const sim::TruthRow& r : rows) {
    if (!outage.contains(r.t) || r.gear == 0) continue;
    if (last_gear > 0 && r.gear != last_gear) ++shifts;
    last_gear = r.gear;
  }
  return shifts;
}

int run_simulate(const SimulateOptions& o) {
  if (o.out.empty()) throw UsageError("simulate: --out DIR is required");
  constexpr double kMaxDuration = 7.0 * 86400.0;  // a week of driving, far beyond any test's need
  if (!(o.duration >= 10.0 && o.duration <= kMaxDuration))
    throw UsageError("simulate: --duration must be 10 s to a week (604800 s)");
  if (!std::isfinite(o.snr_db) || o.snr_db < -60.0 || o.snr_db > 120.0)
    throw UsageError("simulate: --snr must be -60..120 dB");
  if (!std::isfinite(o.pulses_per_km) || o.pulses_per_km <= 0.0)
    throw UsageError("simulate: --pulses-per-km must be positive");
  if (!(o.idle_start >= 0.0 && o.idle_start < o.duration)) {
    throw UsageError("simulate: --idle-start must be 0 or more and below --duration");
  }
  if (!(o.skip_downshift >= 0.0 && o.skip_downshift <= 1.0))
    throw UsageError("simulate: --skip-downshift must be 0..1");
  if (!(o.outage_at_skip >= 0.0 && o.outage_at_skip <= o.duration))
    throw UsageError("simulate: --outage-at-skip must be 0 (off) to --duration s");
  if (o.outage_at_skip > 0.0 && (!o.outage.empty() || o.skip_downshift <= 0.0))
    throw UsageError("simulate: --outage-at-skip takes --skip-downshift above 0 and no --outage");
  if (o.skip_drive_on && o.outage_at_skip <= 0.0)
    throw UsageError("simulate: --skip-drive-on goes with --outage-at-skip");
  if (o.rate < 4000 || o.rate > 192000) throw UsageError("simulate: --rate must be 4000..192000 Hz");
  if (!std::isfinite(o.tone_hz) || o.tone_hz < 0.0 || o.tone_hz >= 0.5 * o.rate)
    throw UsageError("simulate: --tone must be 0 (none) or a frequency below half of --rate");
  sim::Outage outage;
  sim::Vehicle vehicle;
  sim::DrivingStyle style{};
  try {
    if (!o.outage.empty()) outage = sim::parse_outage(o.outage);
    if (!(outage.start >= 0.0 && outage.length >= 0.0 && outage.start + outage.length <= kMaxDuration))
      throw std::invalid_argument("outage '" + o.outage +
                                  "': START and LEN must be 0 or more, within a week");
    if (outage.length > 0.0 && outage.start >= o.duration)
      throw std::invalid_argument("outage '" + o.outage + "' starts after the drive's end (--duration " +
                                  std::to_string(static_cast<long long>(o.duration)) + " s)");
    vehicle = sim::vehicle_preset(o.vehicle);
    style = sim::parse_style(o.style);
  } catch (const std::invalid_argument& e) {
    throw UsageError(std::string("simulate: ") + e.what());
  }

  // Simulate beyond the asked duration so the drive can end at a standstill.
  sim::DriveOptions drive_options;
  drive_options.style = style;
  drive_options.duration = o.duration + o.stop_search;
  drive_options.dt = kSignalStep;
  drive_options.seed = o.seed;
  drive_options.skip_downshift = o.skip_downshift;
  sim::Drive drive = sim::simulate_drive(vehicle, drive_options);
  drive.truth.resize(end_at_standstill(drive, o.duration - o.idle_start, o.stop_search));
  prepend_idle(drive, o.idle_start);
  if (drive.truth.back().speed >= 0.05) {
    std::fprintf(stderr, "simulate: no standstill within %.0f s after %.0f s; the drive ends moving\n",
                 o.stop_search, o.duration);
  }
  const double length = drive.truth.back().t;

  // The outage from the first fix missed after the clutch went out for a braking skip: the last fix is
  // the higher gear's, the lower gear is found from the engine alone. The daemon has driven with GPS
  // for kSkipAfter s before, and gets fixes again for kSkipTail s before the drive ends.
  BrakingSkip skip;
  if (o.outage_at_skip > 0.0) {
    constexpr double kSkipAfter = 30.0, kSkipTail = 10.0;
    skip = first_braking_skip(drive, o.idle_start + kSkipAfter, o.skip_drive_on);
    if (skip.clutch_out < 0.0 || std::ceil(skip.clutch_out) + o.outage_at_skip + kSkipTail > length) {
      throw UsageError("simulate: --outage-at-skip: no braking skip-downshift from " +
                       std::to_string(static_cast<int>(o.idle_start + kSkipAfter)) +
                       " s that leaves the outage and " + std::to_string(static_cast<int>(kSkipTail)) +
                       " s of fixes before the drive's end: a longer --duration or another --seed");
    }
    outage = {std::ceil(skip.clutch_out), o.outage_at_skip};
  }

  std::filesystem::create_directories(o.out);
  const std::filesystem::path dir(o.out);

  // Truth at 10 Hz: fine enough to integrate distance and to judge synthesized speed.
  std::vector<sim::TruthRow> truth_rows;
  for (double t = 0.0; t <= length + 1e-9; t += kTruthStep) {
    const sim::TruthSample s = sim::truth_at(drive, t);
    truth_rows.push_back({t, s.speed, s.freq, s.gear});
  }
  sim::write_truth_csv(dir / "truth.csv", truth_rows);

  // Lighter voltage: the engine component follows the true frequency, sample by sample.
  if (!o.no_audio) {
    const std::vector<float> signal = lighter_voltage(drive, o.rate, o.snr_db, o.tone_hz, o.seed + 101);
    const std::vector<std::int16_t> pcm = sim::to_s16(signal);
    sim::write_raw_s16(dir / "drive.raw", pcm);
    sim::write_wav_s16(dir / "drive.wav", pcm, o.rate);
  }

  // GPS: Doppler speed with the receiver's noise (paper eq. (2)), no fix inside the outage, gps_hz epochs
  // a second, each the truth at its instant. The log starts gps_lead seconds before the drive (at rest)
  // so a replaying gpsd has a fix before t = 0, and t = 0 is always 12:00:00 UTC: a player can start the
  // audio when that epoch comes out. (At 1 Hz the same epochs and noise draws as before the option.)
  std::mt19937_64 rng(o.seed + 202);
  std::normal_distribution<double> gps_noise(0.0, 0.05);
  std::vector<sim::NmeaEpoch> epochs;
  const int last_epoch = static_cast<int>(length * o.gps_hz);
  for (int k = -o.gps_lead * o.gps_hz; k <= last_epoch; ++k) {
    const double t = static_cast<double>(k) / o.gps_hz;
    const double v = t < 0.0 ? 0.0 : sim::truth_at(drive, t).speed;
    epochs.push_back({t, outage.contains(t) ? kMissing : std::max(0.0, v + gps_noise(rng))});
  }
  sim::NmeaTrack track;
  track.utc_seconds_of_day = kDriveStartUtc;
  sim::write_nmea_log(dir / "drive.nmea", epochs, track);

  // Generic samples at 1 Hz for `gearpulse fit` / `replay`: speed blanked in the outage, as the daemon
  // would see it.
  sim::ObservationOptions observation;
  observation.seed = o.seed + 303;
  std::vector<sim::SampleRow> sample_rows;
  for (const sim::Observation& ob : sim::observe(drive, observation)) {
    sample_rows.push_back({ob.truth.t, outage.contains(ob.truth.t) ? kMissing : ob.speed, ob.freq});
  }
  sim::write_samples_csv(dir / "samples.csv", sample_rows);

  const double distance = sim::distance_m(truth_rows);
  const int shifts = count_shifts(truth_rows, outage);
  // The same figures for scripts (shell-sourceable).
  std::vector<std::string> summary = {
      "duration_s=" + std::to_string(length),
      "distance_m=" + std::to_string(distance),
      "pulses_per_km=" + std::to_string(o.pulses_per_km),
      "pulses_expected=" + std::to_string(distance / 1000.0 * o.pulses_per_km),
      "outage_start_s=" + std::to_string(outage.start),
      "outage_length_s=" + std::to_string(outage.length),
      "shifts_in_outage=" + std::to_string(shifts),
      "gps_lead_s=" + std::to_string(o.gps_lead),
      "gps_hz=" + std::to_string(o.gps_hz),
      "gps_t0_utc=12:00:00",
  };
  if (skip.clutch_out >= 0.0) {
    summary.push_back("skip_clutch_out_s=" + std::to_string(skip.clutch_out));
    summary.push_back("skip_declutched_s=" + std::to_string(skip.declutched));
    summary.push_back("skip_gears=" + std::to_string(skip.from) + ":" + std::to_string(skip.to));
  }
  sim::write_lines(dir / "drive.env", summary);
  std::printf(
      "simulate: %s %s seed %llu: %.1f s, %.3f km, %.0f pulses at %.1f/km, outage %.0f-%.0f s with %d "
      "shifts, %s\n",
      vehicle.name.c_str(), o.style.c_str(), static_cast<unsigned long long>(o.seed), length,
      distance / 1000.0, distance / 1000.0 * o.pulses_per_km, o.pulses_per_km, outage.start,
      outage.start + outage.length, shifts, o.out.c_str());
  if (skip.clutch_out >= 0.0) {
    std::printf(
        "simulate: outage at the braking skip %d -> %d: clutch out at %.2f s for %.2f s at %.1f km/h\n",
        skip.from, skip.to, skip.clutch_out, skip.declutched,
        3.6 * sim::truth_at(drive, skip.clutch_out).speed);
  }
  return 0;
}

}  // namespace

void add_simulate(CLI::App& app, int& status) {
  auto opts = std::make_shared<SimulateOptions>();
  CLI::App* cmd = app.add_subcommand(
      "simulate", "Write a simulated drive: lighter voltage (raw, wav), NMEA, truth and sample CSVs");
  cmd->add_option("--out", opts->out, "Output directory (created)")->required();
  cmd->add_option("--seed", opts->seed, "Random seed: same seed, same drive")
      ->capture_default_str()
      ->check(CLI::Validator(
          [](const std::string& text) {
            // CLI11 takes "-1" and overflowing digits as some seed: only a whole number that fits.
            std::uint64_t v = 0;
            const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
            return ec == std::errc() && end == text.data() + text.size() && !text.empty()
                       ? std::string()
                       : "a whole number from 0 to 18446744073709551615, not " + text;
          },
          "SEED"));
  cmd->add_option("--duration", opts->duration, "Seconds; the drive ends at the next standstill after it")
      ->capture_default_str();
  cmd->add_option("--outage", opts->outage, "GPS outage START:LEN in seconds (no fix inside)");
  cmd->add_option("--rate", opts->rate, "Audio sample rate (Hz)")->capture_default_str();
  cmd->add_option("--vehicle", opts->vehicle, "Vehicle preset")->capture_default_str();
  cmd->add_option("--style", opts->style, "Driving style: mixed, urban, highway, jam")->capture_default_str();
  cmd->add_option("--snr", opts->snr_db, "Engine component SNR in 50-200 Hz (dB)")->capture_default_str();
  cmd->add_option("--tone", opts->tone_hz, "Fixed interfering tone on the line (Hz, 0 = none)")
      ->capture_default_str();
  cmd->add_option("--pulses-per-km", opts->pulses_per_km, "For the expected pulse count in the summary")
      ->capture_default_str();
  cmd->add_option("--idle-start", opts->idle_start, "Seconds at rest, engine idling, before driving off")
      ->capture_default_str();
  cmd->add_option("--gps-lead", opts->gps_lead, "Seconds of GPS fixes at rest before the drive's t = 0")
      ->capture_default_str()
      ->check(CLI::Range(0, 600));
  cmd->add_option("--gps-hz", opts->gps_hz, "GPS fix sets a second in drive.nmea (times to 0.01 s)")
      ->capture_default_str()
      ->check(CLI::IsMember({1, 2, 5, 10}));
  cmd->add_option("--skip-downshift", opts->skip_downshift,
                  "Share of downshifts under braking that skip a gear (4 -> 2, 5 -> 3), 0..1")
      ->capture_default_str();
  cmd->add_option(
      "--outage-at-skip", opts->outage_at_skip,
      "GPS outage of LEN s from the first braking skip-downshift after 30 s (needs --skip-downshift)");
  cmd->add_flag("--skip-drive-on", opts->skip_drive_on,
                "--outage-at-skip: a skip after which the car drives on in the lower gear (10 s), not one "
                "braking to a stop");
  cmd->add_flag("--no-audio", opts->no_audio, "Only the CSVs and NMEA (a training drive for fit)");
  cmd->callback([opts, &status] { status = run_simulate(*opts); });
}

}  // namespace gearpulse::cli
