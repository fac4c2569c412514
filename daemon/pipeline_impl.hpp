#pragma once
// The state behind a Pipeline (daemon/pipeline.hpp), shared by the two files that run it: pipeline.cpp
// (construction, the outputs, the main thread's calls and the status) and pipeline_tracker.cpp (the tracker
// thread's loop and its steps).
#include <atomic>
#include <chrono>
#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/fix_pairer.hpp"
#include "core/published.hpp"
#include "core/sliding_dft_tracker.hpp"
#include "core/spsc_ring.hpp"
#include "core/synth_output.hpp"
#include "daemon/fault_reporter.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/synthesis_stage.hpp"
#include "drivers/audio_front_end.hpp"
#include "drivers/gpsd_client.hpp"
#include "drivers/late_output.hpp"
#include "drivers/pulse_thread.hpp"
#include "drivers/wake_event.hpp"

namespace gearpulse::daemon {

struct Pipeline::Impl {
  static constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
  // GPS fixes wait this long for the audio window centred on them before they are given up (FixPairer).
  static constexpr double kPairWait = 3.0;

  Impl(const Config& c, ModelHolder& m, TrainingStore& s);

  const Config config;
  ModelHolder& model;
  TrainingStore& store;
  FaultReporter faults;

  std::atomic<double> gps_latency{PipelineTunables{}.gps_latency};
  std::atomic<double> min_snr_db{PipelineTunables{}.min_snr_db};

  // The tracker thread waits on it; the capture thread signals it after each push into the audio ring,
  // the gpsd client's thread after each report, halt() once it has set `stop`. Declared before the devices
  // whose threads signal it, so it outlives them.
  WakeEvent work;

  // Devices.
  LateOutput output;
  std::unique_ptr<PulseThread> pulses;
  std::unique_ptr<GpsdClient> gps;
  mutable std::mutex output_mutex;  // output_error (set by the main thread, read by status queries), dropped,
                                    // write_errors
  std::string output_error;
  // The output's dropped-pulse and failed-write counts as snapshots saw them (snapshots come from several
  // threads: under output_mutex).
  mutable RecentGrowth dropped, write_errors;
  std::chrono::steady_clock::time_point next_output_try;

  AudioFrontEnd audio;  // opened, read and closed by the tracker thread; its status() read by any

  std::thread tracker_thread;
  std::atomic<bool> stop{false};
  std::atomic<bool> tracker_done{false};  // tracker_loop() has returned (its capture closed)

  // Published by the tracker thread.
  std::atomic<std::int64_t> tracker_beat{0};
  std::atomic<std::uint64_t> tracker_turns{0};
  std::atomic<std::uint64_t> late_hops{0};  // hops stepped late, on the GPS of their due time (step())
  Published<SynthOutput> step_output;       // speed, its spread, gear and source of one step, read together
  std::atomic<double> track_freq{kNan};
  std::atomic<double> track_snr{kNan};
  std::atomic<bool> track_confident{false};
  std::atomic<std::uint64_t> pairs_added{0};
  std::atomic<std::uint64_t> pairs_lost{0};  // the main thread did not drain them in time
  // Training pairs from the tracker thread to the main thread, which adds them to the store: the
  // tracker never waits for the store's lock (held by the idle-priority retrainer while it copies, or
  // by a save), so no other process's load can stall it through a priority inversion.
  SpscRing<Sample> pairs{1024};
  std::atomic<double> last_fix_speed{kNan};  // m/s of the last usable fix
  std::atomic<std::int64_t> last_fix_ns{0};  // its receive time, 0 = none yet
  std::atomic<std::uint64_t> ring_drops{0};

  void open_output();
  void open_output_device();
  // The tracker thread's state between two turns of its loop.
  struct Tracking {
    // `pair_wait`: how long a GPS fix waits for its window (kPairWait, and the decision lag on top).
    Tracking(double band_low, double pair_wait) : synthesis(band_low), fixes(pair_wait) {}
    SynthesisStage synthesis;                    // told the tracker's band floor (tracker.band_low)
    ModelPtr model;                              // the one the synthesis uses
    std::unique_ptr<SlidingDftTracker> tracker;  // while audio is open
    std::vector<float> block;                    // one read of the ring
    FixPairer fixes;
    PairSpacing pair_spacing;            // one pair a second of the receiver's clock
    std::uint64_t model_generation = 0;  // ModelHolder::generation() when `model` was taken
    std::int64_t last_rx = 0;            // receive time of the last GPS report looked at
    std::optional<GpsReport> given_fix;  // the newest report a step gave the synthesis
    double last_points_at = 0.0;         // CLOCK_MONOTONIC s when the tracker last gave points
    // s from a hop's time to the latest moment a thread keeping pace steps it (set as the audio opens).
    double hop_due = 0.0;
  };
  bool open_audio(std::unique_ptr<SlidingDftTracker>& tracker);
  void adopt_model(Tracking& k) noexcept;
  bool track_audio(Tracking& k, double now) noexcept;
  // `hop`: a hop of the audio (GPS judged as GpsHistory::for_hop says), not a step on GPS alone.
  void step(Tracking& k, double t, double freq, double snr, bool tracked, bool hop) noexcept;
  void pair_fixes(Tracking& k, double now) noexcept;
  void tracker_loop() noexcept;
};

}  // namespace gearpulse::daemon
