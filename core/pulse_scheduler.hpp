#pragma once
// Phase-continuous speed-pulse train. The scheduler integrates distance as phase, counted in pulses:
// phase(t) = pulses emitted + owed(t), where owed grows at f = speed * pulses_per_km / 1000 and a rising
// edge is due when owed reaches 1. A speed change only changes the slope from that instant on, so no
// pulse is lost or added: over any profile, pulses = distance * pulses_per_km / 1000 within +-1 (as long
// as the frequency stays inside [min_freq_hz, max_freq_hz]).
//
// A pulse high when the speed rises falls as one at the new frequency would (never in the past), so a slow
// pulse does not hold the train back. Below min_freq_hz the train stops: the phase is frozen (a crawl below
// that speed adds no distance) and no edge is scheduled except the fall of a pulse already high. Above
// max_freq_hz the frequency is clamped. The pulses owed are bounded: beyond half a second's pulses at
// max_freq_hz they are dropped and counted (discarded()), so a line that cannot keep up (an output slower
// than its edges, a thread held up for long) does not pay them out after the car has stopped; a caller
// woken late owes far fewer. Pure and real-time safe: time is an argument (CLOCK_MONOTONIC ns in
// the daemon), nothing allocates or throws after construction.
#include <cstdint>
#include <limits>

namespace gearpulse {

struct PulseConfig {
  double pulses_per_km = 2485.0;
  double pulse_width_s = 0.0;   // > 0: fixed high time; 0: high for duty / f
  double duty = 0.5;            // used when pulse_width_s == 0, in (0, 1)
  double min_freq_hz = 0.5;     // below this the train stops
  double max_freq_hz = 2000.0;  // above this the frequency is clamped; a fixed width must fit in 1/max
};

// Throws std::invalid_argument naming the offending field.
void validate(const PulseConfig& config);

enum class EdgeKind : std::uint8_t { kNone, kRise, kFall };

struct PulseEdge {
  static constexpr std::int64_t kNever = std::numeric_limits<std::int64_t>::max();
  std::int64_t t_ns = kNever;
  EdgeKind kind = EdgeKind::kNone;
};

class PulseScheduler {
 public:
  explicit PulseScheduler(const PulseConfig& config, std::int64_t t0_ns = 0);  // validates; may throw

  // New target speed (m/s) from t_ns on. NaN or negative means 0. t_ns earlier than the scheduler's
  // time is taken as its time (changes never rewrite the past).
  void set_speed(std::int64_t t_ns, double speed_mps) noexcept;

  // The next pending edge for the current speed; kind kNone and t_ns kNever if none (stopped, low).
  // Its time may lie before the caller's "now" if the caller is late: emit it at once.
  [[nodiscard]] PulseEdge next_edge() const noexcept;
  // If the next edge is due at or before t_ns, commits and returns it; otherwise returns kNone. The edge
  // counts as made at its scheduled time: a simulation's clock, or a caller whose line only keeps count.
  PulseEdge pop_due(std::int64_t t_ns) noexcept;
  // The same for a caller writing the edge on a line at now_ns: a late edge counts as made when it is
  // written, so a woken-late thread does not write a rise and its fall back to back (a pulse microseconds
  // wide, which a counter misses) nor the next rise straight after a fall; the pulse keeps its width and
  // the low time of max_freq_hz on the line. The count still follows the scheduled phase, so the pulses owed
  // are caught up at up to max_freq_hz. Returns the edge with its scheduled time (how late it was).
  PulseEdge emit_due(std::int64_t now_ns) noexcept;

  [[nodiscard]] double frequency_hz() const noexcept { return freq_; }     // after clamping / stopping
  [[nodiscard]] double speed_mps() const noexcept { return speed_; }       // as last set
  [[nodiscard]] std::uint64_t pulses() const noexcept { return pulses_; }  // rising edges committed
  // Whole pulses dropped from the pulses owed beyond the bound (half a second at max_freq_hz).
  [[nodiscard]] std::uint64_t discarded() const noexcept { return static_cast<std::uint64_t>(discarded_); }
  [[nodiscard]] bool high() const noexcept { return high_; }
  // Distance in pulses integrated up to t_ns (>= the scheduler's time): pulses() + owed phase (less what
  // was discarded()).
  [[nodiscard]] double phase_pulses(std::int64_t t_ns) const noexcept;
  [[nodiscard]] const PulseConfig& config() const noexcept { return config_; }

 private:
  void advance_to(std::int64_t t_ns) noexcept;  // integrates owed_ from t_ to t_ns at freq_
  [[nodiscard]] std::int64_t next_rise_ns() const noexcept;
  PulseEdge commit(std::int64_t t_ns, std::int64_t made_ns) noexcept;  // made_ns: when the line shows it

  PulseConfig config_;
  double min_spacing_ns_;    // 1 / max_freq_hz: rises never come closer, even when catching up
  double min_low_ns_ = 0.0;  // low time at max_freq_hz
  std::int64_t t_;           // time up to which owed_ is integrated
  double owed_ = 0.0;        // phase not yet emitted, in pulses (a rise is due at 1)
  double max_owed_ = 1.0;    // the bound on owed_
  double discarded_ = 0.0;   // phase dropped beyond it, in pulses
  double freq_ = 0.0;        // Hz
  double speed_ = 0.0;       // m/s
  std::uint64_t pulses_ = 0;
  bool high_ = false;
  std::int64_t fall_ns_ = PulseEdge::kNever;  // pending fall while high_
  std::int64_t last_rise_ns_ = std::numeric_limits<std::int64_t>::min() / 2;
  std::int64_t last_fall_ns_ = std::numeric_limits<std::int64_t>::min() / 2;
};

}  // namespace gearpulse
