#include "daemon/change_reporter.hpp"

#include <algorithm>
#include <chrono>
#include <string>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

namespace gearpulse::daemon {

void ChangeReporter::log(const PipelineSnapshot& before, const PipelineSnapshot& now,
                         std::chrono::steady_clock::time_point at) {
  const std::string server = fmt::format("{}:{}", config_.gps.host, config_.gps.port);
  const std::string output = output_target(config_.output);
  // From the connection itself, not from a change between two snapshots: the first connection is often
  // made before the first snapshot is taken.
  if (const bool up = now.gps_state != GpsState::kDisconnected; up != gps_connected_) {
    gps_connected_ = up;
    if (up) spdlog::info("gps: connected to gpsd at {}", server);
  }
  // No fix is a state a receiver under trees or bridges can enter many times a minute: its start is said
  // at once, then at most once a minute with how often it came. A fix is said at the first one, after a
  // spell without one that was said, and after a lost connection; a flap's return is a debug line.
  std::uint64_t no_fix_starts = 0;
  const StateFault::Say no_fix = no_fix_.update(now.gps_state == GpsState::kNoFix, at, no_fix_starts);
  if (no_fix == StateFault::Say::kStart) {
    // How long GPS has really been gone: after a reconnect that can be far more than the timeout.
    // (The source it switches to is said when it switches: after the timeout, not necessarily yet.)
    const std::string times =
        no_fix_starts > 1 ? fmt::format(" ({} times since the last report)", no_fix_starts) : "";
    if (now.gps_age >= 0.0)
      spdlog::warn("gps: no usable fix from gpsd at {} for {:.1f} s{}; check that the antenna sees the sky",
                   server, now.gps_age, times);
    else
      spdlog::warn(
          "gps: no usable fix from gpsd at {} yet{} (a receiver's first fix can take a minute; if "
          "none comes, check that the antenna sees the sky)",
          server, times);
  }
  if (now.gps_state == GpsState::kDisconnected) gps_lost_ = true;
  if (now.gps_state == GpsState::kFix && before.gps_state != GpsState::kFix) {
    limiter_.reset("gps");  // the connection works: its next failure is said at once
    const bool news = !gps_fixed_ || no_fix == StateFault::Say::kEnd || gps_lost_;
    gps_fixed_ = true;
    gps_lost_ = false;
    spdlog::log(news ? spdlog::level::info : spdlog::level::debug, "gps: fix from gpsd at {} ({:.1f} km/h)",
                server, std::max(0.0, now.gps_speed) * 3.6);
  }
  // A receiver's glitch refused: said at once, then at most once a minute with how many more.
  if (now.gps_implausible > before.gps_implausible) {
    std::uint64_t suppressed = 0;
    if (limiter_.allow("gps-implausible", suppressed))
      spdlog::warn(
          "gps: a speed of {:.0f} km/h from gpsd at {} ignored (no car reaches it, or not that fast); "
          "{} such reports so far{}",
          now.gps_last_implausible * 3.6, server, now.gps_implausible,
          suppressed ? fmt::format(" ({} since the last report)", suppressed) : "");
  }
  // A receiver that dead-reckons (a tunnel) reports a fix and a speed it did not measure: taken as no GPS,
  // which a user watching gpsd's own clients would not guess without this line.
  if (now.gps_unmeasured > before.gps_unmeasured) {
    std::uint64_t suppressed = 0;
    if (limiter_.allow("gps-unmeasured", suppressed))
      spdlog::info(
          "gps: gpsd at {} gives a fix by dead reckoning (or time only, or simulated): its speed was not "
          "measured and is taken as no GPS; {} such reports so far{}",
          server, now.gps_unmeasured,
          suppressed ? fmt::format(" ({} since the last report)", suppressed) : "");
  }
  // One count per failed attempt (the backoff spaces them), not per turn of this loop.
  if (now.gps_state == GpsState::kDisconnected && !now.gps_error.empty() &&
      now.gps_failures != gps_failures_seen_) {
    gps_failures_seen_ = now.gps_failures;
    std::uint64_t suppressed = 0;
    if (limiter_.allow("gps", suppressed))
      spdlog::warn(
          "gps: {}; reconnecting with backoff; check that gpsd runs and that gps.host and gps.port name it{}",
          now.gps_error,
          suppressed ? fmt::format(" ({} more failed attempts since the last report)", suppressed) : "");
  }
  // Away from GPS (speed from the engine or coasting through an outage, or none at all) is a state a
  // receiver under trees can enter many times a minute: once the speed has come from GPS, its start and
  // end are said as StateFault says them (two lines a minute at most) and its other flaps are debug lines.
  // Before that, each change is said. Engine <-> coast inside an outage (every declutch) is a debug line.
  const auto outage = [](SpeedSource s) { return s == SpeedSource::kEngine || s == SpeedSource::kCoast; };
  const bool routine = outage(before.source) && outage(now.source);
  const bool before_gps = !gps_source_seen_;
  gps_source_seen_ = gps_source_seen_ || now.source == SpeedSource::kGps;
  std::uint64_t departures = 0;
  const StateFault::Say away = gps_source_seen_
                                   ? away_from_gps_.update(now.source != SpeedSource::kGps, at, departures)
                                   : StateFault::Say::kNothing;
  if (now.source != before.source || away == StateFault::Say::kStart) {
    const std::string change =
        now.source != before.source
            ? fmt::format("{} -> {}", source_name(before.source), source_name(now.source))
            : std::string(source_name(now.source));
    const bool news = away != StateFault::Say::kNothing || (before_gps && !routine);
    spdlog::log(news ? spdlog::level::info : spdlog::level::debug,
                "synthesis: speed source {} at {:.1f} km/h (gear {}){}", change, now.speed * 3.6, now.gear,
                away == StateFault::Say::kStart && departures > 1
                    ? fmt::format(" (GPS left {} times since the last line said so)", departures)
                    : "");
  }
  // A navigator that should be reading the pulses is not: said when the last reader goes (or none is
  // there at start) and when one comes, at most once a minute for a reader that opens and closes often.
  std::uint64_t starts = 0;
  switch (no_reader_.update(now.output_state == OutputState::kNoReader, at, starts)) {
    case StateFault::Say::kStart:
      spdlog::warn(
          "output: no process has {} open; pulses are discarded and counted as unheard ({} so far){}", output,
          now.output_unheard, starts > 1 ? fmt::format(" ({} times since the last report)", starts) : "");
      break;
    case StateFault::Say::kEnd:
      spdlog::info("output: a reader has {} open ({} pulses went unheard in all)", output,
                   now.output_unheard);
      break;
    case StateFault::Say::kNothing:
      break;
  }
  // Writes that fail (a USB adapter unplugged, a PTY's master gone bad): said when they start, at most
  // once a minute, and when none has failed for the 5 s the state lasts (pipeline.cpp, kRecentFault; no
  // write may have been tried meanwhile, so it is not said that they work).
  std::uint64_t failing_starts = 0;
  switch (write_errors_.update(now.output_state == OutputState::kWriteErrors, at, failing_starts)) {
    case StateFault::Say::kStart:
      spdlog::warn(
          "output: writes to {} are failing ({}); pulses are counted but not delivered; check the "
          "device and its cable{}",
          output, now.output_error,
          failing_starts > 1 ? fmt::format(" ({} times since the last report)", failing_starts) : "");
      break;
    case StateFault::Say::kEnd:
      spdlog::info("output: no write to {} has failed for 5 s", output);
      break;
    case StateFault::Say::kNothing:
      break;
  }
  if (now.output_dropped > before.output_dropped) {
    std::uint64_t suppressed = 0;
    if (limiter_.allow("output-dropped", suppressed))
      spdlog::warn(
          "output: the reader of {} is not reading: {} pulse(s) dropped (total {}); pulses that wait in "
          "its queue over 2 s are dropped rather than delivered late",
          output, now.output_dropped - before.output_dropped, now.output_dropped);
  } else if (before.output_state == OutputState::kReaderBehind &&
             now.output_state != OutputState::kReaderBehind) {
    limiter_.reset("output-dropped");
    spdlog::info("output: the reader of {} keeps up again", output);
  }
  if (now.pulses_discarded > before.pulses_discarded) {
    std::uint64_t suppressed = 0;
    if (limiter_.allow("pulses-discarded", suppressed))
      spdlog::warn(
          "output: pulses come due faster than {} takes them: {} owed beyond half a second at "
          "output.max_frequency dropped (total {}); the device is too slow for the rate, or the pulse "
          "thread is held up (set audio.realtime)",
          output, now.pulses_discarded - before.pulses_discarded, now.pulses_discarded);
  }
  // Said once for each thread: audio.realtime that is not granted leaves the thread at the normal
  // priority, which the overrun and pulse lines above would otherwise go on advising to set.
  for (const std::string& thread : now.realtime_refused) {
    if (std::find(before.realtime_refused.begin(), before.realtime_refused.end(), thread) !=
        before.realtime_refused.end())
      continue;
    const int priority =
        thread == "pulse" ? std::min(99, config_.audio.rt_priority + 10) : config_.audio.rt_priority;
    spdlog::warn(
        "realtime: the {} thread was refused SCHED_FIFO at priority {} or the memory lock that "
        "audio.realtime asks for, and runs at the normal priority; grant RLIMIT_RTPRIO and RLIMIT_MEMLOCK "
        "(the unit's LimitRTPRIO=95 honours audio.rt_priority up to 85) or CAP_SYS_NICE and CAP_IPC_LOCK",
        thread, priority);
  }
  if (now.xruns > before.xruns) {
    std::uint64_t suppressed = 0;
    if (limiter_.allow("xrun", suppressed))
      spdlog::warn(
          "audio: {} overrun(s) on {} (total {}); the capture recovered; if they repeat, set audio.realtime "
          "or raise audio.period_frames",
          now.xruns - before.xruns, config_.audio.device, now.xruns);
  }
  if (now.ring_drops > before.ring_drops) {
    std::uint64_t suppressed = 0;
    if (limiter_.allow("ring", suppressed))
      spdlog::warn(
          "audio: the tracker fell behind, {} frames dropped at the ring (total {}); if it repeats, the "
          "machine is too busy: raise audio.ring_seconds or set audio.realtime",
          now.ring_drops - before.ring_drops, now.ring_drops);
  }
  if (now.pairs_lost > before.pairs_lost) {
    std::uint64_t suppressed = 0;
    if (limiter_.allow("pairs", suppressed))
      spdlog::warn(
          "training: {} pair(s) lost waiting for the main thread (total {}); the model learns from the "
          "others, but a busy machine or a slow state_dir disk is behind it",
          now.pairs_lost - before.pairs_lost, now.pairs_lost);
  }
}

}  // namespace gearpulse::daemon
