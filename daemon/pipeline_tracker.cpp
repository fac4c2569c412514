// The tracker thread of a Pipeline (its state: daemon/pipeline_impl.hpp): its loop, the capture it opens
// and reads into the tracker, the steps of the synthesis it publishes, the model it adopts and the training
// pairs it makes.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <optional>
#include <span>
#include <string>

#include <spdlog/spdlog.h>

#include "daemon/pipeline_impl.hpp"
#include "drivers/clock.hpp"

namespace gearpulse::daemon {
namespace {

// Longest wait of the tracker thread without work (audio, a GPS report, a step on GPS alone, an open of
// the capture, stop()): the period of its heartbeat, which the watchdog judges (kStallNs = 5 s). A
// twentieth of that limit, as the pulse thread's: only a wait stretched twenty-fold reads as hung.
constexpr double kTrackerBeat = 0.25;  // s

}  // namespace

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
void Pipeline::Impl::step(Tracking& k, double t, double freq, double snr, bool tracked, bool hop) noexcept {
  // GPS counts while its newest report is usable and younger than the timeout (receive time, so a
  // disagreement between the sound card's clock and the GPS cannot hide a good fix). A hop of a backlog
  // drained late (stepped after the moment a thread keeping pace steps it) takes the report newest at that
  // moment instead, judged then, as it would have stepped in pace: the synthesis does not depend on how the
  // thread was scheduled, and a hop on time gets GPS exactly as judged now (GpsHistory). A step on GPS
  // alone has no hop to be late: it takes GPS as it is now. Lock-free: the gpsd thread never holds up a
  // hop.
  const std::int64_t now_ns = monotonic_ns();
  std::optional<GpsReport> fix;
  if (gps && hop) {
    const GpsHistory::ForHop h = gps->for_hop(std::llround((t + k.hop_due) * 1e9), now_ns);
    fix = h.fix;
    if (h.late) late_hops.fetch_add(1, std::memory_order_relaxed);
    // A backlog after steps on GPS alone (the audio stalled) would go back to a report older than one the
    // synthesis has measured: GPS never runs backwards, the newer one stays (not measured again).
    if (fix && k.given_fix && fix->rx_ns < k.given_fix->rx_ns) fix = k.given_fix;
  } else if (gps) {
    fix = gps->fresh(now_ns);
  }
  if (fix) k.given_fix = fix;
  const SynthesisStage::Step s =
      k.synthesis.step(t, freq, snr, tracked, fix, min_snr_db.load(std::memory_order_relaxed),
                       gps_latency.load(std::memory_order_relaxed));
  track_freq.store(tracked ? freq : kNan, std::memory_order_relaxed);
  track_snr.store(snr, std::memory_order_relaxed);
  track_confident.store(s.confident, std::memory_order_relaxed);
  if (pulses) pulses->set_speed(s.out.speed);
  step_output.publish(s.out);
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
    // oldest would be dropped. (The hops' decided confidence reaches the training pairs through the
    // tracker's history, nearest(): the daemon never pops the decided queue, which overwrites itself.)
    const std::size_t piece = tracker.max_push_frames();
    for (std::size_t at = 0; at < b.frames; at += piece) {
      tracker.push(std::span<const float>(k.block.data() + at, std::min(piece, b.frames - at)));
      TrackPoint p;
      while (tracker.pop(p)) {
        got_points = true;
        k.last_points_at = now;
        step(k, p.t, p.freq, p.snr_db, p.tracked, true);
      }
    }
    if (b.frames < k.block.size()) break;
  }
  ring_drops.store(audio.ring_dropped(), std::memory_order_relaxed);
  return got_points;
}

// Training pairs: the first usable GPS fix of each second (PairSpacing) waits in the FixPairer for the
// window centred on its time.
void Pipeline::Impl::pair_fixes(Tracking& k, double now) noexcept {
  if (gps) {
    if (const auto rep = gps->latest(); rep && rep->rx_ns != k.last_rx) {
      k.last_rx = rep->rx_ns;
      if (rep->usable()) {
        last_fix_speed.store(rep->speed, std::memory_order_relaxed);
        last_fix_ns.store(rep->rx_ns, std::memory_order_relaxed);
        const double t_fix = rep->rx_ns * 1e-9 - gps_latency.load(std::memory_order_relaxed);
        if (k.pair_spacing.take(rep->fix_time, t_fix))
          (void)k.fixes.add({t_fix, wall_now() - (now - t_fix), rep->speed});
      }
    }
  }
  if (k.fixes.waiting() == 0) return;
  // With a decision lag a fix waits until the hops about its instant are decided (and a hop more: the
  // window centred on it may lie after the latest hop), so that its pair takes the decided confidence.
  // Without a tracker none is served (they wait, and are given up after the pairer's longest wait).
  double served = kNan;
  if (k.tracker) {
    const int lag_hops = k.tracker->decision_lag_hops();
    served = k.tracker->latest_time() - (lag_hops > 0 ? (lag_hops + 1) * config.tracker.hop : 0.0);
  }
  for (const PendingFix& f : k.fixes.take_due(now, served)) {
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
  Tracking k(config.tracker.band_low, kPairWait + config.tracker.decision_lag);
  k.model_generation = model.generation();
  k.model = model.get();
  k.synthesis.set_model(k.model);
  // Without audio the synthesis steps on GPS alone, one step per hop and window; with audio only when
  // the tracker has given no points for longer than audio ever pauses. That silence is judged by the
  // clock the points arrive on, not by their time stamps: those lag it by the capture's latency (a
  // period and more), and a step stamped "now" would run ahead of every point still to come.
  const double no_audio_step_s = 2.0 * config.tracker.hop + config.tracker.window;
  double audio_stall_s = no_audio_step_s;

  while (!stop.load(std::memory_order_relaxed)) {
    const std::int64_t now_ns = monotonic_ns();
    tracker_beat.store(now_ns, std::memory_order_relaxed);
    tracker_turns.fetch_add(1, std::memory_order_relaxed);
    const double now = now_ns * 1e-9;
    adopt_model(k);
    if (audio.open_due(std::chrono::steady_clock::now()) && open_audio(k.tracker)) {
      k.block.assign(std::max<std::size_t>(config.audio.period_frames, 256), 0.0f);
      // Audio arrives a period at a time: only a wait longer than two of them is a stall.
      const double period_s = audio.period_frames() / static_cast<double>(audio.rate());
      audio_stall_s = no_audio_step_s + 2.0 * period_s;
      // When a thread keeping pace steps a hop at the latest (GpsHistory::for_hop): its window ends half a
      // window after its time; its last frame reaches the ring within a period (a sound card delivers a
      // period at a time, its time stamps counting the frames in its buffer); the thread steps it before
      // the next hop's window ends, a hop later; and a source may hold up to a hop more that its time stamps
      // do not count (the test harness' FIFO and file plugin: its hops are stepped 0.19 s after their time,
      // 0.09 s more than the window's half and a period). A hop stepped after that waited behind others: a
      // backlog drained late. (The tracker gives each hop at once, whatever its decision lag.)
      k.hop_due = config.tracker.window / 2.0 + period_s + 2.0 * config.tracker.hop;
      k.last_points_at = now;
    }
    const bool got_points = k.tracker && track_audio(k, now);
    // Without audio (or while it stalls) the synthesis still runs on GPS, one step per hop.
    const bool audio_silent = !k.tracker || now - k.last_points_at > audio_stall_s;
    if (!got_points && audio_silent && now - k.synthesis.last_step_time() > no_audio_step_s)
      step(k, now - config.tracker.window / 2.0, kNan, kNan, false, false);
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
}  // namespace gearpulse::daemon
