#include "daemon/pipeline.hpp"

#include <time.h>

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

#include <alsa/asoundlib.h>
#include <spdlog/spdlog.h>

#include "core/pulse_scheduler.hpp"
#include "core/sliding_dft_tracker.hpp"
#include "core/speed_synth.hpp"
#include "core/spsc_ring.hpp"
#include "daemon/log_limiter.hpp"
#include "daemon/watchdog.hpp"
#include "drivers/alsa_capture.hpp"
#include "drivers/clock.hpp"
#include "drivers/gpio_output.hpp"
#include "drivers/gpsd_client.hpp"
#include "drivers/pty_output.hpp"
#include "drivers/pulse_output.hpp"
#include "drivers/pulse_thread.hpp"

namespace gearpulse::daemon {
namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
// The tracker thread wakes at least this often, with or without audio.
constexpr auto kTrackerPoll = std::chrono::milliseconds(10);
// GPS fixes wait this long for the audio window centred on them before they are given up.
constexpr double kPairWait = 3.0;

// libasound prints its own multi-line diagnostics to stderr on every failed open; the daemon logs one
// rate-limited line naming the device instead.
void quiet_alsa_errors(const char*, int, const char*, int, const char*, ...) {}

double wall_now() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<double>(ts.tv_sec) + ts.tv_nsec * 1e-9;
}

PcmFormat format_of(const std::string& name) {
  if (name == "S32_LE") return PcmFormat::kS32;
  if (name == "FLOAT_LE") return PcmFormat::kFloat;
  return PcmFormat::kS16;
}

// Between tries to open an output device that would not open (a GPIO line still held by another
// process, a USB GPIO adapter that enumerates after the daemon started).
constexpr auto kOutputRetry = std::chrono::seconds(2);
// The output is "reader-behind" while pulses were dropped (the reader's queue full) within this time.
constexpr std::chrono::nanoseconds kReaderBehind = std::chrono::seconds(5);

// What the pulse thread drives: the device once it is open; until then a stand-in that counts the pulses.
// The device is attached once, by the main thread, while the pulse thread runs: the thread finds it
// through an atomic pointer at its next edge, and it is freed only after the thread has stopped.
class LateOutput final : public PulseOutput {
 public:
  void attach(std::unique_ptr<PulseOutput> device) noexcept {
    device_ = std::move(device);
    current_.store(device_.get(), std::memory_order_release);
  }
  [[nodiscard]] bool attached() const noexcept { return current_.load(std::memory_order_acquire) != &none_; }
  void rise() noexcept override { current_.load(std::memory_order_acquire)->rise(); }
  void fall() noexcept override { current_.load(std::memory_order_acquire)->fall(); }
  [[nodiscard]] std::uint64_t errors() const noexcept override {
    return current_.load(std::memory_order_acquire)->errors();
  }
  [[nodiscard]] std::uint64_t dropped() const noexcept override {
    return current_.load(std::memory_order_acquire)->dropped();
  }
  [[nodiscard]] bool has_reader() const noexcept override {
    return current_.load(std::memory_order_acquire)->has_reader();
  }
  [[nodiscard]] std::uint64_t unheard() const noexcept override {
    return current_.load(std::memory_order_acquire)->unheard();
  }
  [[nodiscard]] std::string describe() const override {
    return current_.load(std::memory_order_acquire)->describe();
  }

 private:
  NullPulseOutput none_;
  std::unique_ptr<PulseOutput> device_;
  std::atomic<PulseOutput*> current_{&none_};
};

// A GPS fix waiting for the engine frequency of the audio window centred on it.
struct PendingFix {
  double t = 0.0;      // CLOCK_MONOTONIC s of the fix (receive time - latency)
  double wall = 0.0;   // the same instant on the wall clock, for the training store
  double speed = 0.0;  // m/s
};

}  // namespace

struct Pipeline::Impl {
  Impl(const Config& c, ModelHolder& m, TrainingStore& s) : config(c), model(m), store(s) {}

  const Config config;
  ModelHolder& model;
  TrainingStore& store;
  LogLimiter limiter;

  std::atomic<double> gps_latency{PipelineTunables{}.gps_latency};
  std::atomic<double> min_snr_db{PipelineTunables{}.min_snr_db};

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

  // Audio: owned by the tracker thread once started; stats read under audio_mutex.
  mutable std::mutex audio_mutex;
  std::unique_ptr<SpscRing<float>> ring;
  std::unique_ptr<AlsaCapture> capture;
  std::string audio_error;
  std::uint64_t audio_opens = 0;

  std::thread tracker_thread;
  std::atomic<bool> stop{false};
  std::atomic<bool> tracker_done{false};  // tracker_loop() has returned (its capture closed)

  // Published by the tracker thread.
  std::atomic<std::int64_t> tracker_beat{0};
  std::atomic<double> speed{0.0};
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
  bool open_audio(std::unique_ptr<SlidingDftTracker>& tracker);
  void close_audio();
  void tracker_loop() noexcept;
  void report(const std::string& key, spdlog::level::level_enum level, const std::string& text);
  void clear_fault(const std::string& key, const std::string& text);
};

void Pipeline::Impl::report(const std::string& key, spdlog::level::level_enum level,
                            const std::string& text) {
  std::uint64_t suppressed = 0;
  if (!limiter.allow(key, suppressed)) return;
  if (suppressed)
    spdlog::log(level, "{} (repeated {} times since the last report)", text, suppressed);
  else
    spdlog::log(level, "{}", text);
}

void Pipeline::Impl::clear_fault(const std::string& key, const std::string& text) {
  limiter.reset(key);
  spdlog::info("{}", text);
}

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
    report("output", spdlog::level::err,
           fmt::format("output: {}; pulses are counted but not emitted; retrying every {} s", e.what(),
                       kOutputRetry.count()));
    return;
  }
  const std::string name = device->describe();
  output.attach(std::move(device));
  bool was_failing = false;
  {
    std::lock_guard lock(output_mutex);
    was_failing = !output_error.empty();
    output_error.clear();
  }
  const std::string text = fmt::format("output: {} at {} pulses/km", name, o.pulses_per_km);
  if (was_failing)
    clear_fault("output", text + " (opened on a retry)");
  else
    spdlog::info("{}", text);
}

bool Pipeline::Impl::open_audio(std::unique_ptr<SlidingDftTracker>& tracker) {
  const AudioConfig& a = config.audio;
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
  std::unique_ptr<SpscRing<float>> new_ring;
  std::unique_ptr<AlsaCapture> new_capture;
  try {
    new_ring =
        std::make_unique<SpscRing<float>>(static_cast<std::size_t>(std::max(1.0, a.ring_seconds * a.rate)));
    new_capture = std::make_unique<AlsaCapture>(ac, *new_ring);
  } catch (const std::exception& e) {
    std::lock_guard lock(audio_mutex);
    audio_error = e.what();
    return false;
  }
  // Also the tracker's tables and the capture thread may not be had (memory, a thread limit): tried again
  // as a device that will not open is, never an exception out of the tracker's thread.
  try {
    const gearpulse::TrackerConfig tc = tracker_config_of(config.tracker, new_capture->rate());
    std::string error;
    tracker = SlidingDftTracker::create(tc, error);
    if (!tracker) {
      std::lock_guard lock(audio_mutex);
      audio_error = "tracker cannot run on " + new_capture->describe() + ": " + error;
      return false;
    }
    new_capture->start();
  } catch (const std::exception& e) {
    tracker.reset();
    std::lock_guard lock(audio_mutex);
    audio_error = std::string("cannot start the capture: ") + e.what();
    return false;
  }
  std::lock_guard lock(audio_mutex);
  ring = std::move(new_ring);
  capture = std::move(new_capture);
  audio_error.clear();
  ++audio_opens;
  return true;
}

void Pipeline::Impl::close_audio() {
  std::unique_ptr<AlsaCapture> old_capture;
  std::unique_ptr<SpscRing<float>> old_ring;
  {
    std::lock_guard lock(audio_mutex);
    old_capture = std::move(capture);
    old_ring = std::move(ring);
  }
  if (old_capture) old_capture->stop();
}

void Pipeline::Impl::tracker_loop() noexcept {
  // The same SpeedSynthesizer `gearpulse replay` runs, stepped live.
  SpeedSynthesizer synth;
  std::shared_ptr<const GearModel> current_model = model.get();
  synth.set_model(current_model);
  std::unique_ptr<SlidingDftTracker> tracker;
  std::vector<float> block;
  std::array<PendingFix, 64> pending{};
  std::size_t pending_count = 0;
  std::int64_t last_rx = 0;
  double last_step_t = 0.0;
  std::uint64_t read_frames = 0;  // ring frame index of the next frame to read
  double next_frame_t = 0.0;      // expected CLOCK_MONOTONIC s of that frame
  bool stream_started = false;
  auto next_audio_try = std::chrono::steady_clock::now();
  auto backoff = std::chrono::milliseconds(500);
  bool audio_was_up = false;
  StateFault audio_lost;            // the open capture lost its device and is being reopened
  StateFault audio_frozen;          // its periods repeat (AlsaCaptureStats::frozen)
  StateFault audio_stalled;         // it delivers nothing (AlsaCaptureStats::stalled)
  std::uint64_t repeated_seen = 0;  // AlsaCaptureStats::repeated when the last hole was looked at
  // Without audio the synthesis steps on GPS alone, one step per hop and window; with audio only when
  // the tracker has given no points for longer than audio ever pauses. That silence is judged by the
  // clock the points arrive on, not by their time stamps: those lag it by the capture's latency (a
  // period and more), and a step stamped "now" would run ahead of every point still to come.
  const double no_audio_step_s = 2.0 * config.tracker.hop + config.tracker.window;
  double audio_stall_s = no_audio_step_s;
  double last_points_at = 0.0;  // CLOCK_MONOTONIC s when the tracker last gave points

  FixNovelty fixes;  // which fixes the synthesis has measured (gpsd may report one fix more than once)
  const auto step = [&](double t, double freq, double snr, bool tracked) {
    // GPS counts while its newest report is usable and younger than the timeout (receive time, so a
    // disagreement between the sound card's clock and the GPS cannot hide a good fix). The synthesis
    // steps at every hop and gets that fix at each, measuring it once.
    double gps_speed = kNan;
    bool gps_new = false;
    if (gps) {
      if (const auto r = gps->fresh(monotonic_ns())) {
        gps_speed = r->speed;
        gps_new = fixes.is_new(*r);
      }
    }
    const bool confident =
        tracked && std::isfinite(freq) && snr >= min_snr_db.load(std::memory_order_relaxed);
    track_freq.store(tracked ? freq : kNan, std::memory_order_relaxed);
    track_snr.store(snr, std::memory_order_relaxed);
    track_confident.store(confident, std::memory_order_relaxed);
    t = std::max(t, last_step_t);
    last_step_t = t;
    // The synthesis steps at every hop: its motion, mode changes and evidence are per second, so the hop
    // rate only makes its output fresher. A hop below the SNR gate reads as no frequency.
    const SynthOutput out = synth.step(t, gps_speed, confident ? freq : kNan, gps_new);
    if (pulses) pulses->set_speed(out.speed);
    speed.store(out.speed, std::memory_order_relaxed);
    gear.store(out.gear, std::memory_order_relaxed);
    source.store(out.source, std::memory_order_relaxed);
  };

  while (!stop.load(std::memory_order_relaxed)) {
    const std::int64_t now_ns = monotonic_ns();
    tracker_beat.store(now_ns, std::memory_order_relaxed);
    const double now = now_ns * 1e-9;

    // A retrained model takes over between two steps.
    if (auto m = model.get(); m != current_model) {
      current_model = std::move(m);
      if (!synth.set_model(current_model))
        report("model", spdlog::level::err,
               "synthesis: cannot use the new model (" + std::to_string(current_model->gears.size()) +
                   " gears is more than it supports); keeping the previous one");
    }

    // Audio: open with backoff while it fails; the daemon runs on GPS alone meanwhile.
    if (!tracker && std::chrono::steady_clock::now() >= next_audio_try) {
      if (open_audio(tracker)) {
        std::string describe;
        {
          std::lock_guard lock(audio_mutex);
          describe = capture->describe();
        }
        clear_fault("audio", "audio: capturing from " + describe);
        backoff = std::chrono::milliseconds(500);
        read_frames = 0;
        stream_started = false;
        audio_was_up = true;
        block.assign(std::max<std::size_t>(config.audio.period_frames, 256), 0.0f);
        // Audio arrives a period at a time: only a wait longer than two of them is a stall.
        audio_stall_s =
            no_audio_step_s + 2.0 * capture->period_frames() / static_cast<double>(capture->rate());
        last_points_at = now;
      } else {
        std::string error;
        {
          std::lock_guard lock(audio_mutex);
          error = audio_error;
        }
        report("audio", spdlog::level::err,
               fmt::format("audio: {}; retrying in {:.1f} s (the delay grows to 10 s), speed follows GPS "
                           "meanwhile (without a fix it coasts down from the last speed)",
                           error, static_cast<double>(backoff.count()) / 1000.0));
        next_audio_try = std::chrono::steady_clock::now() + backoff;
        backoff = std::min(backoff * 2, std::chrono::milliseconds(10'000));
      }
    }

    bool got_points = false;
    if (tracker) {
      SpscRing<float>& r = *ring;
      for (int burst = 0; burst < 64; ++burst) {
        const std::size_t n = r.read_bulk(std::span<float>(block));
        if (n == 0) break;
        std::int64_t t_ns = 0;
        const double rate = capture->rate();
        if (capture->frame_time(read_frames, t_ns)) {
          const double t0 = t_ns * 1e-9;
          if (!stream_started) {
            tracker->start(t0);
            stream_started = true;
          } else {
            // Frames lost before the ring show as a forward jump of the sample clock: mark the hole so
            // no window spans it, then re-anchor (small differences are drift corrections).
            const double gap_frames = (t0 - next_frame_t) * rate;
            if (gap_frames > std::max(64.0, config.audio.period_frames / 2.0)) {
              tracker->skip(static_cast<std::uint64_t>(std::llround(gap_frames)));
              // Repeated periods left out by the capture make a hole too; that one is no loss.
              const std::uint64_t repeated = capture->stats().repeated;
              if (repeated == repeated_seen)
                report("audio-hole", spdlog::level::warn,
                       "audio: " + std::to_string(std::llround(gap_frames)) +
                           " frames lost before the ring (overrun, device restart or a stalled source); "
                           "tracking resumes after the hole");
              repeated_seen = repeated;
            }
            tracker->retime(t0);
          }
          next_frame_t = t0;
        }
        next_frame_t += n / rate;
        read_frames += n;
        // Pushed in pieces of at most half the tracker's output queue of hops, drained after each: a
        // backlog read in one pass (a stall) or a long period at short hops holds more hops than the
        // queue, whose oldest would be dropped.
        const std::size_t piece = tracker->max_push_frames();
        for (std::size_t at = 0; at < n; at += piece) {
          tracker->push(std::span<const float>(block.data() + at, std::min(piece, n - at)));
          TrackPoint p;
          while (tracker->pop(p)) {
            got_points = true;
            last_points_at = now;
            step(p.t, p.freq, p.snr_db, p.tracked);
          }
        }
        if (n < block.size()) break;
      }
      ring_drops.store(r.dropped(), std::memory_order_relaxed);
    }
    // Without audio (or while it stalls) the synthesis still runs on GPS, one step per hop.
    const bool audio_silent = !tracker || now - last_points_at > audio_stall_s;
    if (!got_points && audio_silent && now - last_step_t > no_audio_step_s) {
      step(now - config.tracker.window / 2.0, kNan, kNan, false);
    }

    // Training pairs: each new GPS fix waits for the window centred on its time.
    if (gps) {
      if (const auto rep = gps->latest(); rep && rep->rx_ns != last_rx) {
        last_rx = rep->rx_ns;
        if (rep->usable()) {
          last_fix_speed.store(rep->speed, std::memory_order_relaxed);
          last_fix_ns.store(rep->rx_ns, std::memory_order_relaxed);
        }
        if (rep->usable() && pending_count < pending.size()) {
          const double t_fix = rep->rx_ns * 1e-9 - gps_latency.load(std::memory_order_relaxed);
          pending[pending_count++] = {t_fix, wall_now() - (now - t_fix), rep->speed};
        }
      }
    }
    if (pending_count > 0) {
      const double served = tracker ? tracker->latest_time() : kNan;
      std::size_t keep = 0;
      for (std::size_t i = 0; i < pending_count; ++i) {
        const PendingFix f = pending[i];
        if (tracker && std::isfinite(served) && f.t <= served) {
          const TrackPoint p = tracker->at(f.t);
          if (p.tracked && std::isfinite(p.freq) && p.snr_db >= min_snr_db.load(std::memory_order_relaxed)) {
            if (!pairs.try_push(Sample{f.wall, f.speed, p.freq}))
              pairs_lost.fetch_add(1, std::memory_order_relaxed);
          }
        } else if (now - f.t < kPairWait) {
          pending[keep++] = f;
        }
      }
      pending_count = keep;
    }

    if (audio_was_up && tracker) {
      // A lost device (a USB card unplugged) is reopened by the capture thread. It, audio that freezes and
      // audio that stalls are each said when they start and when they end; a device that comes and goes
      // (a loose connector) at most once a minute (StateFault).
      const AlsaCaptureStats s = capture->stats();
      const auto at = std::chrono::steady_clock::now();
      std::uint64_t starts = 0;
      const auto meanwhile = [&starts](std::string_view what) {
        return starts > 1 ? fmt::format(" ({} {} time(s) more since the last report)", what, starts - 1)
                          : std::string();
      };
      using Say = StateFault::Say;
      if (s.running) {
        const Say say = audio_lost.update(!s.streaming, at, starts);
        if (say == Say::kStart)
          spdlog::warn(
              "audio: capture from {} interrupted (ALSA error {}: {}); the driver keeps reopening it{}",
              config.audio.device, s.last_error, ::snd_strerror(s.last_error), meanwhile("lost"));
        else if (say == Say::kEnd)
          spdlog::info("audio: capture from {} resumed ({} reopen(s) so far)", config.audio.device,
                       s.reopens);
      }
      if (const Say say = audio_frozen.update(s.frozen, at, starts); say == Say::kStart)
        spdlog::warn(
            "audio: {} gives the same samples period after period (a source that has stopped, or digital "
            "silence); they are not used, and speed follows GPS (without a fix it coasts down from the last "
            "speed), until they change{}",
            config.audio.device, meanwhile("frozen"));
      else if (say == Say::kEnd)
        spdlog::info("audio: samples from {} change again", config.audio.device);
      if (const Say say = audio_stalled.update(s.stalled, at, starts); say == Say::kStart)
        spdlog::warn(
            "audio: no samples from {} for {:.1f} s (the device is open but delivers nothing); speed follows "
            "GPS (without a fix it coasts down from the last speed) until they come again{}",
            config.audio.device, s.silent_s, meanwhile("stalled"));
      else if (say == Say::kEnd)
        spdlog::info("audio: samples from {} come again", config.audio.device);
    }
    if (!got_points) std::this_thread::sleep_for(kTrackerPoll);
  }
  close_audio();
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
  if (d.config.log.level != "trace") snd_lib_error_set_handler(&quiet_alsa_errors);
  d.open_output();
  GpsdConfig gc;
  gc.host = d.config.gps.host;
  gc.port = std::to_string(d.config.gps.port);
  gc.no_fix_timeout = std::chrono::milliseconds(static_cast<long>(d.config.gps.timeout * 1000));
  d.gps = std::make_unique<GpsdClient>(gc);
  d.gps->start();
  d.stop.store(false);
  d.tracker_done.store(false);
  d.tracker_beat.store(monotonic_ns());
  d.tracker_thread = std::thread([&d] { d.tracker_loop(); });
}

void Pipeline::service() {
  Impl& d = *impl_;
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
  {
    std::lock_guard lock(d.audio_mutex);
    if (d.capture) {
      const AlsaCaptureStats a = d.capture->stats();
      s.audio_state = !a.streaming ? AudioState::kRecovering
                      : a.frozen   ? AudioState::kFrozen
                      : a.stalled  ? AudioState::kStalled
                                   : AudioState::kRunning;
      s.xruns = a.xruns;
      s.audio_error = a.last_error != 0 && !a.streaming
                          ? fmt::format("ALSA error {}: {}", a.last_error, ::snd_strerror(a.last_error))
                          : "";
    } else {
      s.audio_state = AudioState::kRetrying;
      s.audio_error = d.audio_error;
    }
  }
  s.ring_drops = d.ring_drops.load(std::memory_order_relaxed);
  const double f = d.track_freq.load(std::memory_order_relaxed);
  s.tracker_freq = std::isfinite(f) ? f : -1.0;
  s.tracker_snr_db = d.track_snr.load(std::memory_order_relaxed);
  s.tracker_confident = d.track_confident.load(std::memory_order_relaxed);
  s.pairs_added = d.pairs_added.load(std::memory_order_relaxed);
  s.pairs_lost = d.pairs_lost.load(std::memory_order_relaxed);
  if (d.tracker_thread.joinable())
    beats.push_back({"tracker", d.tracker_beat.load(std::memory_order_relaxed)});
  s.stalled = stalled_threads(beats, now);
  return s;
}

}  // namespace gearpulse::daemon
