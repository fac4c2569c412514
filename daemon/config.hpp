#pragma once
// The daemon's configuration (TOML). Every key has a default; unknown keys, wrong types and out-of-range
// values are errors of the form "file:line: key: reason", raised before any device is opened.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/pulse_scheduler.hpp"
#include "core/sliding_dft_tracker.hpp"

namespace gearpulse::daemon {

struct AudioConfig {
  std::string device = "default";  // ALSA PCM name
  unsigned rate = 48000;           // Hz
  unsigned channels = 1;           // channels negotiated with the PCM
  int channel = -1;                // channel fed to the tracker; -1 = mix of all channels ("mix")
  std::string format = "auto";     // "auto", "S16_LE", "S32_LE", "FLOAT_LE"
  unsigned period_frames = 1024;   // ALSA period size
  bool realtime = false;           // SCHED_FIFO capture and pulse threads (+ mlockall)
  int rt_priority = 50;            // SCHED_FIFO priority when realtime
  double ring_seconds = 2.0;       // capacity of the capture ring
};

// The [tracker] section as the file gives it; tracker_config_of makes the core tracker's TrackerConfig of
// it for the rate the device gave.
struct TrackerSection {
  double band_low = TrackerConfig{}.band_lo_hz;   // Hz
  double band_high = TrackerConfig{}.band_hi_hz;  // Hz
  double window = TrackerConfig{}.window_s;       // s
  double hop = TrackerConfig{}.hop_s;             // s
  // s each hop's confidence is decided later (TrackerConfig::decision_lag_s) for the training pairs (their
  // fixes wait as long); the live speed takes every hop at once either way. 0: decided at once
  double decision_lag = 0.0;
  double min_snr_db = -10.0;  // below this a tracked hop is not trusted for training or synthesis
};

inline constexpr double kMaxGpsLatency = 5.0;  // s: the largest gps.latency accepted

struct GpsConfig {
  std::string host = "127.0.0.1";
  unsigned port = 2947;
  double latency = 0.0;  // s between the fix's true instant and its receive time (<= kMaxGpsLatency)
  double timeout = 1.5;  // s without a usable fix before GPS counts as lost
};

enum class OutputKind { kPty, kGpio, kNone };

struct OutputConfig {
  OutputKind kind = OutputKind::kPty;
  std::string path = "/run/gearpulse/pulse";  // pty: symlink to the slave side
  std::string chip = "gpiochip0";             // gpio
  unsigned line = 17;                         // gpio line offset
  double pulses_per_km = 2485.0;
  double pulse_width = 0.0005;  // s high per pulse (used when duty is 0)
  double duty = 0.0;            // 0 = fixed pulse_width; otherwise fraction of the period
  double min_frequency = 0.5;   // Hz; below it the train stops (standstill)
  double max_frequency = 1000;  // Hz; above it the train clamps
};

// Where the pulses go, as the status and the log name it: the PTY's path or "chip:line"; "" for none.
[[nodiscard]] std::string output_target(const OutputConfig& o);
// The pulse train's settings as the scheduler takes them (fixed width when duty is 0).
[[nodiscard]] PulseConfig pulse_config_of(const OutputConfig& o) noexcept;
// The tracker's settings for capture at `sample_rate_hz` (the rate the device gave).
[[nodiscard]] gearpulse::TrackerConfig tracker_config_of(const TrackerSection& t,
                                                         double sample_rate_hz) noexcept;

struct ModelConfig {
  std::string state_dir = "/var/lib/gearpulse";
  double retrain_interval = 600.0;         // s between retrain attempts
  std::size_t min_new_samples = 600;       // new training pairs needed before a retrain
  std::size_t replace_min_samples = 3600;  // a trained model is replaced only by a fit on this many
  // The learning schedule of a young model (daemon/learning_schedule.hpp): the first fit once this many
  // steady pairs lie in one gear's window, refits after learn_first_refit, 2x, 4x ... s of moving, up to
  // learn_young_time s of moving (0 = no schedule: the interval rule alone).
  std::size_t learn_cluster_pairs = 40;
  double learn_first_refit = 60.0;
  double learn_young_time = 960.0;
  double store_hours = 50.0;            // hours of driving the stored pairs cover
  std::size_t max_samples = 1'000'000;  // hard cap on the store, whatever the age
  double save_interval = 300.0;         // s between periodic saves of the training store
};

struct ControlConfig {
  std::string socket = "/run/gearpulse/control.sock";
  unsigned max_clients = 32;
};

struct LogConfig {
  std::string level = "info";  // trace, debug, info, warn, error, critical, off
};

struct Config {
  AudioConfig audio;
  TrackerSection tracker;
  GpsConfig gps;
  OutputConfig output;
  ModelConfig model;
  ControlConfig control;
  LogConfig log;
  std::string source;  // file it came from, for messages
};

// One line: "file:line: key: reason" (line omitted when unknown).
struct ConfigError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// The longest config file read: the shipped one is under 10 kB, and neither a device that never ends
// (/dev/zero) nor a file written by mistake makes the daemon allocate more than this.
inline constexpr std::size_t kMaxConfigBytes = std::size_t{1} << 20;

// Parses and validates; throws ConfigError, also for anything but a regular file (a FIFO would block the
// reader) and for a file longer than kMaxConfigBytes. Relative paths in the file (output.path,
// model.state_dir, control.socket) are taken from the file's directory, not the daemon's working directory.
[[nodiscard]] Config load_config(const std::string& path);
// Same from text (tests); `source_name` is used in messages, relative paths are taken from `base_dir`
// (left as written when it is empty).
[[nodiscard]] Config parse_config(std::string_view text, const std::string& source_name,
                                  const std::filesystem::path& base_dir = {});

[[nodiscard]] const char* to_string(OutputKind kind) noexcept;

// Keys whose change takes effect on SIGHUP; everything else needs a restart.
// Returns the dotted names of the keys that differ between `a` and `b` and need a restart, in the
// documentation's order.
[[nodiscard]] std::vector<std::string> restart_required_changes(const Config& a, const Config& b);

}  // namespace gearpulse::daemon
