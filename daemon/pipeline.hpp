#pragma once
// The live chain: ALSA capture -> ring -> tracker; gpsd -> speed synthesis -> pulse output; aligned
// (speed, frequency) pairs -> training store. Devices are opened inside their threads and retried with
// backoff, so a missing sound card or gpsd never stops the daemon; faults show in the snapshot.
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/speed_synth.hpp"
#include "daemon/config.hpp"
#include "daemon/model_store.hpp"
#include "daemon/pipeline_state.hpp"
#include "daemon/training_store.hpp"

namespace gearpulse::daemon {

struct PipelineSnapshot {
  // Synthesis / output.
  double speed = 0.0;     // m/s carried by the pulse train
  double speed_sd = 0.0;  // m/s, the synthesis' spread about it through an outage (0 on GPS)
  SpeedSource source = SpeedSource::kNone;
  int gear = 0;
  std::uint64_t pulses = 0;
  std::uint64_t pulses_discarded = 0;  // owed beyond the scheduler's bound, dropped (PulseScheduler)
  double pulse_frequency = 0.0;        // Hz
  OutputState output_state = OutputState::kOff;
  std::string output_error;
  std::uint64_t output_dropped = 0;  // pulses a present reader did not take (PulseOutput::dropped)
  std::uint64_t output_unheard = 0;  // pulses emitted with no reader there (PulseOutput::unheard)
  // GPS.
  GpsState gps_state = GpsState::kDisconnected;
  double gps_speed = -1.0;  // m/s of the last fix, < 0 none
  int gps_mode = 0;
  double gps_age = -1.0;  // s since the last usable fix, < 0 never
  std::uint64_t gps_reconnects = 0;
  std::uint64_t gps_failures = 0;     // failed connection attempts and lost connections
  std::uint64_t gps_implausible = 0;  // reports whose speed the GpsSpeedGate refused
  double gps_last_implausible = 0.0;  // m/s, the last refused speed
  std::uint64_t gps_unmeasured = 0;   // reports of a dead-reckoned, time-only or simulated fix
  std::string gps_error;
  // Audio and tracker.
  AudioState audio_state = AudioState::kStopped;
  std::string audio_error;
  // While recovering or retrying: the ALSA step that failed last ("open", "read", ...; "" when none did),
  // the attempts to open the device since the audio went, and the wall-clock time of the last (s, < 0
  // none). "", 0 and -1 while a device streams.
  std::string audio_failed_step;
  std::uint64_t audio_open_attempts = 0;
  double audio_last_attempt = -1.0;
  std::uint64_t audio_reopens = 0;  // lost devices the open capture has reopened
  std::uint64_t xruns = 0;
  std::uint64_t ring_drops = 0;
  double tracker_freq = -1.0;  // Hz, < 0 not tracked
  // Turns of the tracker thread's loop: one per wake-up (audio pushed, a GPS report, a step on GPS alone,
  // an open of the capture, its heartbeat or stop()); the status's tracker.turns.
  std::uint64_t tracker_turns = 0;
  // Hops stepped late, after a backlog, on the GPS of the moment a thread keeping pace would have stepped
  // them; 0 while the thread keeps pace. The status's tracker.late_hops.
  std::uint64_t tracker_late_hops = 0;
  double tracker_snr_db = 0.0;
  bool tracker_confident = false;
  // Training.
  std::uint64_t pairs_added = 0;
  std::uint64_t pairs_lost = 0;  // made while the main thread did not take them (it was held up)
  // Threads whose heartbeat is stale (empty = all alive).
  std::vector<std::string> stalled;
  std::vector<std::string> missing;  // components not built into this daemon
  // Threads refused the real-time set-up audio.realtime asks for (SCHED_FIFO, the memory lock).
  std::vector<std::string> realtime_refused;
};

// Settings that may change on SIGHUP without restarting the threads.
struct PipelineTunables {
  double gps_latency = GpsConfig{}.latency;
  double min_snr_db = TrackerSection{}.min_snr_db;
};

class Pipeline {
 public:
  Pipeline(const Config& config, ModelHolder& model, TrainingStore& store);
  ~Pipeline();
  Pipeline(const Pipeline&) = delete;
  Pipeline& operator=(const Pipeline&) = delete;

  void start();
  // The main thread's periodic chores that may block briefly: tries again to open an output device that
  // would not open (every few seconds until it does).
  void service();
  // Moves the training pairs the tracker has made since the last call into the store (the main
  // thread's job, at least every few seconds: the hand-over holds about 100 s of 10 Hz fixes).
  // Returns how many the store took.
  std::size_t drain_pairs();
  // Stops the pulse train (the output is left low) and tells the tracker to stop making training pairs,
  // without waiting for anything: what is learned can be saved before the joins of stop().
  void halt() noexcept;
  // Stops every thread (halt() first); the output is left low. Joining the tracker waits for the capture
  // thread, which a device that never returns from a read can hold.
  void stop() noexcept;
  void set_tunables(const PipelineTunables& tunables) noexcept;
  [[nodiscard]] PipelineSnapshot snapshot() const;
  // The same as seen at CLOCK_MONOTONIC `now_ns` (ages and heartbeats are judged against it), so a
  // test can look at the pipeline as it will be seconds later.
  [[nodiscard]] PipelineSnapshot snapshot(std::int64_t now_ns) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace gearpulse::daemon
