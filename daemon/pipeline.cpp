#include "daemon/pipeline.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>

#include <spdlog/spdlog.h>

#include "core/fix_pairer.hpp"
#include "core/pulse_scheduler.hpp"
#include "core/sliding_dft_tracker.hpp"
#include "core/spsc_ring.hpp"
#include "daemon/fault_reporter.hpp"
#include "daemon/synthesis_stage.hpp"
#include "daemon/watchdog.hpp"
#include "drivers/audio_front_end.hpp"
#include "drivers/clock.hpp"
#include "drivers/gpio_output.hpp"
#include "drivers/gpsd_client.hpp"
#include "drivers/late_output.hpp"
#include "drivers/pty_output.hpp"
#include "drivers/pulse_output.hpp"
#include "drivers/pulse_thread.hpp"
#include "drivers/wake_event.hpp"

namespace gearpulse::daemon {
namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
// Longest wait of the tracker thread without work (audio, a GPS report, a step on GPS alone, an open of
// the capture, stop()): the period of its heartbeat, which the watchdog judges (kStallNs = 5 s). A
// twentieth of that limit, as the pulse thread's: only a wait stretched twenty-fold reads as hung.
constexpr double kTrackerBeat = 0.25;  // s
// GPS fixes wait this long for the audio window centred on them before they are given up (FixPairer).
constexpr double kPairWait = 3.0;

PcmFormat format_of(const std::string& name) {
  if (name == "S32_LE") return PcmFormat::kS32;
  if (name == "FLOAT_LE") return PcmFormat::kFloat;
  return PcmFormat::kS16;
}

AlsaCaptureConfig capture_config_of(const AudioConfig& a) {
  AlsaCaptureConfig ac;
  ac.device = a.device;
  ac.rate = a.rate;
  ac.channels = a.channels;
  ac.format = format_of(a.format);
  ac.channel = a.channel;
  ac.period_frames = a.period_frames;
  ac.realtime = a.realtime;
  ac.rt_priority = a.rt_priority;
  ac.lock_memory = a.realtime;
  return ac;
}

// Between tries to open an output device that would not open (a GPIO line still held by another
// process, a USB GPIO adapter that enumerates after the daemon started).
constexpr auto kOutputRetry = std::chrono::seconds(2);
// The output is "reader-behind" while pulses were dropped (the reader's queue full) within this time.
constexpr std::chrono::nanoseconds kReaderBehind = std::chrono::seconds(5);

}  // namespace

struct Pipeline::Impl {
  Impl(const Config& c, ModelHolder& m, TrainingStore& s)
      : config(c),
        model(m),
        store(s),
        faults(config.audio.device),
        audio(capture_config_of(config.audio), config.audio.ring_seconds, &work) {}

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
  mutable std::mutex output_mutex;  // output_error: set by the main thread, read by status queries
  std::string output_error;
  // Last dropped-pulse count a snapshot saw and when it changed (snapshots come from several threads).
  mutable std::atomic<std::uint64_t> dropped_seen{0};
  mutable std::atomic<std::int64_t> dropped_at_ns{0};
  std::chrono::steady_clock::time_point next_output_try;

  AudioFrontEnd audio;  // opened, read and closed by the tracker thread; its status() read by any

  std::thread tracker_thread;
  std::atomic<bool> stop{false};
  std::atomic<bool> tracker_done{false};  // tracker_loop() has returned (its capture closed)

  // Published by the tracker thread.
  std::atomic<std::int64_t> tracker_beat{0};
  std::atomic<std::uint64_t> tracker_turns{0};
  std::atomic<double> speed{0.0};
  std::atomic<double> speed_sd{0.0};
  std::atomic<int> gear{0};
  std::atomic<SpeedSource> source{SpeedSource::kNone};
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
    explicit Tracking(double band_low) : synthesis(band_low) {}
    SynthesisStage synthesis;                    // told the tracker's band floor (tracker.band_low)
    ModelPtr model;                              // the one the synthesis uses
    std::unique_ptr<SlidingDftTracker> tracker;  // while audio is open
    std::vector<float> block;                    // one read of the ring
    FixPairer fixes{kPairWait};
    std::uint64_t model_generation = 0;  // ModelHolder::generation() when `model` was taken
    std::int64_t last_rx = 0;            // receive time of the last GPS report looked at
    double last_points_at = 0.0;         // CLOCK_MONOTONIC s when the tracker last gave points
  };
  bool open_audio(std::unique_ptr<SlidingDftTracker>& tracker);
  void adopt_model(Tracking& k) noexcept;
  bool track_audio(Tracking& k, double now) noexcept;
  void step(Tracking& k, double t, double freq, double snr, bool tracked) noexcept;
  void pair_fixes(Tracking& k, double now) noexcept;
  void tracker_loop() noexcept;
};

void Pipeline::Impl::open_output() {
  const OutputConfig& o = config.output;
  PulseThreadConfig pc;
  pc.pulse = pulse_config_of(o);
  pc.realtime = config.audio.realtime;
  pc.rt_priority = std::min(99, config.audio.rt_priority + 10);
  pc.lock_memory = config.audio.realtime;
  pulses = std::make_unique<PulseThread>(output, pc);
  pulses->set_speed(0.0);
  pulses->start();
  if (o.kind == OutputKind::kNone) {
    spdlog::info("output: none (pulses are counted, not emitted) at {} pulses/km", o.pulses_per_km);
    return;
  }
  open_output_device();
}

// Opens the configured device and hands it to the pulse thread; on failure the pulses go on being
// counted and the main thread tries again every kOutputRetry (Pipeline::service()).
void Pipeline::Impl::open_output_device() {
  const OutputConfig& o = config.output;
  next_output_try = std::chrono::steady_clock::now() + kOutputRetry;
  std::unique_ptr<PulseOutput> device;
  try {
    switch (o.kind) {
      case OutputKind::kPty: {
        // As for the control socket and the state directory: a missing directory is made.
        const std::filesystem::path dir = std::filesystem::path(o.path).parent_path();
        std::error_code ec;
        if (!dir.empty() && !std::filesystem::create_directories(dir, ec) && ec)
          throw std::runtime_error("cannot create the directory " + dir.string() + " for " + o.path + ": " +
                                   ec.message());
        device = std::make_unique<PtyOutput>(o.path);
        break;
      }
      case OutputKind::kGpio:
        device = std::make_unique<GpioOutput>(o.chip, o.line);
        break;
      case OutputKind::kNone:
        return;
    }
  } catch (const std::exception& e) {
    {
      std::lock_guard lock(output_mutex);
      output_error = e.what();
    }
    faults.report("output", spdlog::level::err,
                  fmt::format("output: {}; pulses are counted but not emitted; retrying every {} s", e.what(),
                              kOutputRetry.count()));
    return;
  }
  const std::string name = device->describe();
  if (!output.attach(std::move(device))) return;  // attached already (service() checks attached() first)
  bool was_failing = false;
  {
    std::lock_guard lock(output_mutex);
    was_failing = !output_error.empty();
    output_error.clear();
  }
  const std::string text = fmt::format("output: {} at {} pulses/km", name, o.pulses_per_km);
  if (was_failing)
    faults.clear("output", text + " (opened on a retry)");
  else
    spdlog::info("{}", text);
}

// Opens the capture with backoff (AudioFrontEnd) and, for the rate the device gave, the tracker; the
// daemon runs on GPS alone while it fails.
bool Pipeline::Impl::open_audio(std::unique_ptr<SlidingDftTracker>& tracker) {
  const bool opened = audio.open(
      std::chrono::steady_clock::now(), [&](unsigned rate, const std::string& describe) -> std::string {
        std::string error;
        tracker = SlidingDftTracker::create(tracker_config_of(config.tracker, rate), error);
        return tracker ? std::string() : "tracker cannot run on " + describe + ": " + error;
      });
  if (opened) {
    faults.clear("audio", "audio: capturing from " + audio.describe());
    return true;
  }
  tracker.reset();
  faults.report("audio", spdlog::level::err,
                fmt::format("audio: {}; retrying in {:.1f} s (the delay grows to 10 s), speed follows GPS "
                            "meanwhile (without a fix it coasts down from the last speed)",
                            audio.error(), static_cast<double>(audio.retry_delay().count()) / 1000.0));
  return false;
}

// Publishes one step of the synthesis: to the pulse thread and to the snapshot.
void Pipeline::Impl::step(Tracking& k, double t, double freq, double snr, bool tracked) noexcept {
  // GPS counts while its newest report is usable and younger than the timeout (receive time, so a
  // disagreement between the sound card's clock and the GPS cannot hide a good fix). Lock-free: the
  // gpsd thread never holds up a hop.
  const std::optional<GpsReport> fix = gps ? gps->fresh(monotonic_ns()) : std::nullopt;
  const SynthesisStage::Step s =
      k.synthesis.step(t, freq, snr, tracked, fix, min_snr_db.load(std::memory_order_relaxed),
                       gps_latency.load(std::memory_order_relaxed));
  track_freq.store(tracked ? freq : kNan, std::memory_order_relaxed);
  track_snr.store(snr, std::memory_order_relaxed);
  track_confident.store(s.confident, std::memory_order_relaxed);
  if (pulses) pulses->set_speed(s.out.speed);
  speed.store(s.out.speed, std::memory_order_relaxed);
  speed_sd.store(s.out.speed_sd, std::memory_order_relaxed);
  gear.store(s.out.gear, std::memory_order_relaxed);
  source.store(s.out.source, std::memory_order_relaxed);
}

// A retrained model takes over between two steps. The holder's lock (which the idle-priority retrainer
// takes to swap the model) is taken only when its generation says the model changed, not at every turn.
void Pipeline::Impl::adopt_model(Tracking& k) noexcept {
  const std::uint64_t generation = model.generation();
  if (generation == k.model_generation) return;
  k.model_generation = generation;
  auto m = model.get();
  if (m == k.model) return;
  k.model = std::move(m);
  if (!k.synthesis.set_model(k.model)) faults.post({FaultNote::Kind::kModelRejected, k.model->gears.size()});
}

// Reads what the ring holds (at most 64 blocks) into the tracker and steps the synthesis at each point
// it gives. True if it gave any.
bool Pipeline::Impl::track_audio(Tracking& k, double now) noexcept {
  bool got_points = false;
  SlidingDftTracker& tracker = *k.tracker;
  for (int burst = 0; burst < 64; ++burst) {
    const AudioBlock b = audio.read(std::span<float>(k.block));
    if (b.frames == 0) break;
    if (b.first) {
      tracker.start(b.t0);
    } else if (b.timed) {
      // A hole before the block is marked so no window spans it, then the clock is re-anchored (small
      // differences are drift corrections).
      if (b.hole > 0) {
        tracker.skip(b.hole);
        if (b.hole_lost) faults.post({FaultNote::Kind::kAudioHole, b.hole});
      }
      tracker.retime(b.t0);
    }
    // Pushed in pieces of at most half the tracker's output queue of hops, drained after each: a backlog
    // read in one pass (a stall) or a long period at short hops holds more hops than the queue, whose
    // oldest would be dropped.
    const std::size_t piece = tracker.max_push_frames();
    for (std::size_t at = 0; at < b.frames; at += piece) {
      tracker.push(std::span<const float>(k.block.data() + at, std::min(piece, b.frames - at)));
      TrackPoint p;
      while (tracker.pop(p)) {
        got_points = true;
        k.last_points_at = now;
        step(k, p.t, p.freq, p.snr_db, p.tracked);
      }
    }
    if (b.frames < k.block.size()) break;
  }
  ring_drops.store(audio.ring_dropped(), std::memory_order_relaxed);
  return got_points;
}

// Training pairs: each new usable GPS fix waits in the FixPairer for the window centred on its time.
void Pipeline::Impl::pair_fixes(Tracking& k, double now) noexcept {
  if (gps) {
    if (const auto rep = gps->latest(); rep && rep->rx_ns != k.last_rx) {
      k.last_rx = rep->rx_ns;
      if (rep->usable()) {
        last_fix_speed.store(rep->speed, std::memory_order_relaxed);
        last_fix_ns.store(rep->rx_ns, std::memory_order_relaxed);
        const double t_fix = rep->rx_ns * 1e-9 - gps_latency.load(std::memory_order_relaxed);
        (void)k.fixes.add({t_fix, wall_now() - (now - t_fix), rep->speed});
      }
    }
  }
  if (k.fixes.waiting() == 0) return;
  for (const PendingFix& f : k.fixes.take_due(now, k.tracker ? k.tracker->latest_time() : kNan)) {
    const TrackPoint p = k.tracker->at(f.t);
    const auto pair =
        training_pair(f, p.freq, p.snr_db, p.tracked, min_snr_db.load(std::memory_order_relaxed));
    if (pair && !pairs.try_push(*pair)) pairs_lost.fetch_add(1, std::memory_order_relaxed);
  }
}

// The live data flow, one turn for each piece of work: audio front end -> tracker -> synthesis -> pulse
// thread, and GPS fixes -> fix pairer -> training pairs for the main thread. Between turns the thread
// waits on `work` until the next thing it does by the clock: a step on GPS alone, an open of the capture,
// its heartbeat.
void Pipeline::Impl::tracker_loop() noexcept {
  Tracking k(config.tracker.band_low);
  k.model_generation = model.generation();
  k.model = model.get();
  k.synthesis.set_model(k.model);
  // Without audio the synthesis steps on GPS alone, one step per hop and window; with audio only when
  // the tracker has given no points for longer than audio ever pauses. That silence is judged by the
  // clock the points arrive on, not by their time stamps: those lag it by the capture's latency (a
  // period and more), and a step stamped "now" would run ahead of every point still to come.
  const double no_audio_step_s = 2.0 * config.tracker.hop + config.tracker.window;
  // A decision lag holds the points back as many hops more (at the stream's start and after a hole).
  const double lag_s = std::round(config.tracker.decision_lag / config.tracker.hop) * config.tracker.hop;
  double audio_stall_s = no_audio_step_s + lag_s;

  while (!stop.load(std::memory_order_relaxed)) {
    const std::int64_t now_ns = monotonic_ns();
    tracker_beat.store(now_ns, std::memory_order_relaxed);
    tracker_turns.fetch_add(1, std::memory_order_relaxed);
    const double now = now_ns * 1e-9;
    adopt_model(k);
    if (audio.open_due(std::chrono::steady_clock::now()) && open_audio(k.tracker)) {
      k.block.assign(std::max<std::size_t>(config.audio.period_frames, 256), 0.0f);
      // Audio arrives a period at a time: only a wait longer than two of them is a stall.
      audio_stall_s =
          no_audio_step_s + lag_s + 2.0 * audio.period_frames() / static_cast<double>(audio.rate());
      k.last_points_at = now;
    }
    const bool got_points = k.tracker && track_audio(k, now);
    // Without audio (or while it stalls) the synthesis still runs on GPS, one step per hop.
    const bool audio_silent = !k.tracker || now - k.last_points_at > audio_stall_s;
    if (!got_points && audio_silent && now - k.synthesis.last_step_time() > no_audio_step_s)
      step(k, now - config.tracker.window / 2.0, kNan, kNan, false);
    pair_fixes(k, now);
    if (k.tracker) faults.audio(audio.stats(), std::chrono::steady_clock::now());
    if (k.tracker && audio.has_frames()) continue;  // more than one turn's reading was waiting
    // The wait took the signals given before it, and this turn then read the ring and the newest GPS
    // report and looked at `stop`: what was pushed, reported or asked since has signalled `work` again.
    double until = now + kTrackerBeat;
    // The next step on GPS alone (the conditions above, as times).
    const double gps_step_at = k.synthesis.last_step_time() + no_audio_step_s;
    until =
        std::min(until, k.tracker ? std::max(gps_step_at, k.last_points_at + audio_stall_s) : gps_step_at);
    if (!audio.is_open()) {
      const auto to_open = audio.next_open() - std::chrono::steady_clock::now();
      until = std::min(until, now + std::chrono::duration<double>(to_open).count());
    }
    // A microsecond past it: the comparisons above are strict.
    work.wait_until(static_cast<std::int64_t>(std::ceil(until * 1e9)) + 1000);
  }
  audio.close();
  tracker_done.store(true);
}

Pipeline::Pipeline(const Config& config, ModelHolder& model, TrainingStore& store)
    : impl_(std::make_unique<Impl>(config, model, store)) {
  set_tunables({config.gps.latency, config.tracker.min_snr_db});
}

Pipeline::~Pipeline() {
  stop();
}

void Pipeline::start() {
  Impl& d = *impl_;
  if (d.config.log.level != "trace") quiet_alsa_library_errors();
  d.open_output();
  GpsdConfig gc;
  gc.host = d.config.gps.host;
  gc.port = std::to_string(d.config.gps.port);
  gc.no_fix_timeout = std::chrono::milliseconds(static_cast<long>(d.config.gps.timeout * 1000));
  d.gps = std::make_unique<GpsdClient>(gc, [&d](const GpsReport&) { d.work.signal(); });
  d.gps->start();
  d.stop.store(false);
  d.tracker_done.store(false);
  d.tracker_beat.store(monotonic_ns());
  d.tracker_thread = std::thread([&d] { d.tracker_loop(); });
}

void Pipeline::service() {
  Impl& d = *impl_;
  d.faults.say_notes();
  if (d.pulses && d.config.output.kind != OutputKind::kNone && !d.output.attached() &&
      std::chrono::steady_clock::now() >= d.next_output_try)
    d.open_output_device();
}

std::size_t Pipeline::drain_pairs() {
  Impl& d = *impl_;
  std::size_t added = 0;
  while (Sample* p = d.pairs.front()) {
    if (d.store.add(*p)) ++added;
    d.pairs.pop();
  }
  d.pairs_added.fetch_add(added, std::memory_order_relaxed);
  return added;
}

void Pipeline::halt() noexcept {
  Impl& d = *impl_;
  // The pulse train first: the output goes low now, whatever stop()'s joins then wait for.
  if (d.pulses) {
    d.pulses->set_speed(0.0);
    d.pulses->stop();  // leaves the output low
  }
  d.stop.store(true);
  d.work.signal();  // after the flag: the tracker thread sees it when its wait returns, or does not wait
}

void Pipeline::stop() noexcept {
  Impl& d = *impl_;
  halt();
  if (d.tracker_thread.joinable()) {
    // The tracker thread closes the capture, whose thread may sit in a read the device does not
    // return from (a stalled USB card, a FIFO whose writer paused): say so rather than hang in silence.
    constexpr auto kPatience = std::chrono::seconds(3);
    const auto deadline = std::chrono::steady_clock::now() + kPatience;
    while (!d.tracker_done.load() && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    if (!d.tracker_done.load())
      spdlog::warn("stop: the audio capture has not returned from the device for {} s ({}); still waiting",
                   kPatience.count(), d.config.audio.device);
    d.tracker_thread.join();
  }
  d.faults.say_notes();  // what the tracker thread posted last
  if (d.gps) d.gps->stop();
}

void Pipeline::set_tunables(const PipelineTunables& tunables) noexcept {
  impl_->gps_latency.store(tunables.gps_latency);
  impl_->min_snr_db.store(tunables.min_snr_db);
}

PipelineSnapshot Pipeline::snapshot() const {
  return snapshot(monotonic_ns());
}

PipelineSnapshot Pipeline::snapshot(std::int64_t now) const {
  const Impl& d = *impl_;
  PipelineSnapshot s;
  s.speed = d.speed.load(std::memory_order_relaxed);
  s.speed_sd = d.speed_sd.load(std::memory_order_relaxed);
  s.source = d.source.load(std::memory_order_relaxed);
  s.gear = d.gear.load(std::memory_order_relaxed);
  // Heartbeats of the threads that should be running, for the watchdog.
  std::vector<ThreadBeat> beats;
  if (d.pulses) {
    const PulseThreadStatus ps = d.pulses->status();
    beats.push_back({"pulse", ps.heartbeat_ns, !ps.running});
    s.pulses = ps.pulses;
    s.pulse_frequency = d.pulses->target_speed() * d.config.output.pulses_per_km / 1000.0;
    if (s.pulse_frequency < d.config.output.min_frequency) s.pulse_frequency = 0.0;
    s.pulse_frequency = std::min(s.pulse_frequency, d.config.output.max_frequency);
  }
  if (d.pulses) {
    {
      std::lock_guard lock(d.output_mutex);
      s.output_error = d.output_error;
    }
    // A reader that has not taken a pulse for kReaderBehind: the count grew within that time.
    s.output_dropped = d.output.dropped();
    s.output_unheard = d.output.unheard();
    if (const std::uint64_t seen = d.dropped_seen.load(std::memory_order_relaxed); s.output_dropped != seen) {
      d.dropped_seen.store(s.output_dropped, std::memory_order_relaxed);
      d.dropped_at_ns.store(now, std::memory_order_relaxed);
    }
    const std::int64_t dropped_at = d.dropped_at_ns.load(std::memory_order_relaxed);
    const bool reader_behind = dropped_at > 0 && now - dropped_at < kReaderBehind.count();
    if (!s.output_error.empty())
      s.output_state = OutputState::kError;
    else if (d.output.errors() > 0)
      s.output_state = OutputState::kWriteErrors;
    else if (reader_behind)
      s.output_state = OutputState::kReaderBehind;
    else if (!d.output.has_reader())
      s.output_state = OutputState::kNoReader;
    else
      s.output_state = d.config.output.kind == OutputKind::kNone ? OutputState::kOff : OutputState::kOk;
  }
  if (d.gps) {
    beats.push_back({"gps", d.gps->heartbeat_ns()});
    const GpsdStatus g = d.gps->status();
    s.gps_reconnects = g.connects > 0 ? g.connects - 1 : 0;
    s.gps_error = g.last_error;
    const auto r = d.gps->latest();
    if (g.state != GpsdState::kConnected)
      s.gps_state = GpsState::kDisconnected;
    else
      s.gps_state = d.gps->has_gps(now) ? GpsState::kFix : GpsState::kNoFix;
    if (r) s.gps_mode = r->mode;
    // Age and speed of the last usable fix, also through an outage (how long GPS has been gone). A fix
    // the pipeline thread has not taken yet is already the state's: the speed comes with it.
    std::int64_t fix_ns = d.last_fix_ns.load(std::memory_order_relaxed);
    double fix_speed = d.last_fix_speed.load(std::memory_order_relaxed);
    if (r && r->usable() && r->rx_ns > fix_ns) {
      fix_ns = r->rx_ns;
      fix_speed = r->speed;
    }
    if (fix_ns > 0) {
      s.gps_speed = fix_speed;
      s.gps_age = (now - fix_ns) * 1e-9;
    }
    s.gps_failures = g.failures;
    s.gps_implausible = g.implausible;
    s.gps_last_implausible = g.last_implausible;
    // Its errors are about the connection: once connected again they are history.
    if (s.gps_state != GpsState::kDisconnected) s.gps_error.clear();
  }
  const AudioFrontEndStatus a = d.audio.status();
  if (a.open) {
    s.audio_state = !a.stats.streaming ? AudioState::kRecovering
                    : a.stats.frozen   ? AudioState::kFrozen
                    : a.stats.stalled  ? AudioState::kStalled
                                       : AudioState::kRunning;
    s.xruns = a.stats.xruns;
    s.audio_error = a.error;
    s.audio_reopens = a.stats.reopens;
  } else {
    s.audio_state = AudioState::kRetrying;
    s.audio_error = a.error;
  }
  s.audio_failed_step = to_string(a.failed_step);
  s.audio_open_attempts = a.open_attempts;
  s.audio_last_attempt = a.last_attempt > 0.0 ? a.last_attempt : -1.0;
  s.ring_drops = d.ring_drops.load(std::memory_order_relaxed);
  const double f = d.track_freq.load(std::memory_order_relaxed);
  s.tracker_freq = std::isfinite(f) ? f : -1.0;
  s.tracker_snr_db = d.track_snr.load(std::memory_order_relaxed);
  s.tracker_confident = d.track_confident.load(std::memory_order_relaxed);
  s.pairs_added = d.pairs_added.load(std::memory_order_relaxed);
  s.pairs_lost = d.pairs_lost.load(std::memory_order_relaxed);
  if (d.tracker_thread.joinable())
    beats.push_back({"tracker", d.tracker_beat.load(std::memory_order_relaxed)});
  s.tracker_turns = d.tracker_turns.load(std::memory_order_relaxed);
  s.stalled = stalled_threads(beats, now);
  return s;
}

}  // namespace gearpulse::daemon
