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
#include <system_error>
#include <thread>

#include <spdlog/spdlog.h>

#include "core/fix_pairer.hpp"
#include "core/pulse_scheduler.hpp"
#include "core/sliding_dft_tracker.hpp"
#include "core/spsc_ring.hpp"
#include "daemon/fault_reporter.hpp"
#include "daemon/pipeline_impl.hpp"
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
// An output fault counted within this time is current: "reader-behind" while pulses were dropped (the
// reader's queue full), "write-errors" while writes failed.
constexpr std::chrono::nanoseconds kRecentFault = std::chrono::seconds(5);

}  // namespace

Pipeline::Impl::Impl(const Config& c, ModelHolder& m, TrainingStore& s)
    : config(c),
      model(m),
      store(s),
      faults(config.audio.device),
      audio(capture_config_of(config.audio), config.audio.ring_seconds, &work) {}

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

Pipeline::Pipeline(const Config& config, ModelHolder& model, TrainingStore& store)
    : impl_(std::make_unique<Impl>(config, model, store)) {
  set_tunables({config.gps.latency, config.tracker.min_snr_db});
}

Pipeline::~Pipeline() {
  stop();
}

void Pipeline::start() {
  Impl& d = *impl_;
  show_alsa_library_errors(spdlog::should_log(spdlog::level::trace));
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
  const SynthOutput out = d.step_output.read();  // one step's, whole
  s.speed = out.speed;
  s.speed_sd = out.speed_sd;
  s.source = out.source;
  s.gear = out.gear;
  // Heartbeats of the threads that should be running, for the watchdog.
  std::vector<ThreadBeat> beats;
  // The output's count of unheard pulses before the pulse thread's count of all: the thread counts a pulse
  // before the output does (PulseThread::run), so read in this order the part is never more than the whole.
  const std::uint64_t unheard = d.pulses ? d.output.unheard() : 0;
  if (d.pulses) {
    const PulseThreadStatus ps = d.pulses->status();
    beats.push_back({"pulse", ps.heartbeat_ns, !ps.running});
    s.pulses = ps.pulses;
    s.pulses_discarded = ps.discarded;
    if (ps.realtime_refused) s.realtime_refused.emplace_back("pulse");
    s.pulse_frequency = d.pulses->target_speed() * d.config.output.pulses_per_km / 1000.0;
    if (s.pulse_frequency < d.config.output.min_frequency) s.pulse_frequency = 0.0;
    s.pulse_frequency = std::min(s.pulse_frequency, d.config.output.max_frequency);
  }
  if (d.pulses) {
    // A reader that has not taken a pulse, writes that fail: their counts grew within kRecentFault. The
    // counts are read under the lock too, so that snapshots taken at once by two threads see them in order.
    std::uint64_t errors = 0;
    bool reader_behind = false, write_errors = false;
    {
      std::lock_guard lock(d.output_mutex);
      s.output_error = d.output_error;
      s.output_dropped = d.output.dropped();
      errors = d.output.errors();
      reader_behind = d.dropped.grew_recently(s.output_dropped, now, kRecentFault.count());
      write_errors = d.write_errors.grew_recently(errors, now, kRecentFault.count());
    }
    s.output_unheard = unheard;
    if (!s.output_error.empty())
      s.output_state = OutputState::kError;
    else if (write_errors) {
      s.output_state = OutputState::kWriteErrors;
      const int last = d.output.last_error();
      s.output_error = fmt::format("{} write(s) failed, the last: {}", errors,
                                   last != 0 ? std::error_code(last, std::generic_category()).message()
                                             : std::string("unknown error"));
    } else if (reader_behind)
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
    s.gps_unmeasured = g.unmeasured;
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
  s.tracker_late_hops = d.late_hops.load(std::memory_order_relaxed);
  s.stalled = stalled_threads(beats, now);
  if (a.stats.realtime_refused) s.realtime_refused.emplace_back("capture");
  return s;
}

}  // namespace gearpulse::daemon