#pragma once
// How late GPS speed is against the engine frequency. A receiver reports the speed of a moment before it
// delivers the fix (its own filter, the NMEA sentence, the read: 0.2-1 s), and an OBD logger polls speed
// and revs at different moments of a round. Taken as current, a late fix contradicts the gear whose line
// the revs follow whenever the car gains or loses speed (moving off at 2 m/s^2, a fix 0.5 s late is 1 m/s
// slow), and the clutch, whose revs say nothing of the speed, explains both.
//
// Learned from the drive's own fixes by cross-correlation: for each fix faster than kMinSpeed, taken while
// the speed changes by kMinChange a second or more (at a steady speed every candidate fits alike but for
// the revs' noise, which a reading interpolated between two others averages down), and for each candidate
// delay d (0 to kMaxDelay in steps of kStep), the revs at t - d (interpolated between those noted) are
// turned into a speed by the nearest gear of the ladder, and the fix's squared log-departure from it,
// bounded by kClip (a shift or a declutch, which no gear explains, counts alike at every delay), is
// averaged with a memory of kMemory fixes. The delay is the candidate of least average, placed between
// its neighbours by a parabola through the three; 0 until a fix has told the candidates apart.
//
// It also keeps the last few seconds of revs and of the filter's own speed, which the synthesis takes a
// fix's delay out with (SpeedSynthesizer::filter_step).
//
// Fixed arrays, no allocation.
#include <array>
#include <span>

namespace gearpulse {

class GpsDelay {
 public:
  static constexpr double kStep = 0.1;      // s between candidate delays
  static constexpr double kMaxDelay = 1.0;  // s: a receiver reports a fix within its period (1 s at 1 Hz)
  static constexpr int kCandidates = 11;    // 0, kStep, ..., kMaxDelay

  // Every step: the engine frequency at step time t (Hz; NaN or <= 0: none).
  void note_freq(double t, double freq) noexcept { revs_.add(t, freq); }
  // After every step: the speed the filter holds (its belief's mean) at t.
  void note_speed(double t, double speed) noexcept { speed_.add(t, speed); }
  // A new fix: GPS speed `gps` (m/s) delivered at step time t (after note_freq for that step); `theta` the
  // ladder's gears ((m/s)/Hz).
  void learn(double t, double gps, std::span<const double> theta) noexcept;
  // s: how much older the speed of a fix is than the revs of the step it comes with.
  [[nodiscard]] double delay() const noexcept { return delay_; }
  // The revs, or the filter's speed, at time t, interpolated between the values noted around it (false,
  // `value` untouched, if no two values 2.5 s apart or closer bracket it, or t is before the oldest kept).
  [[nodiscard]] bool revs_at(double t, double& value) const noexcept { return revs_.at(t, value); }
  [[nodiscard]] bool speed_at(double t, double& value) const noexcept { return speed_.at(t, value); }

 private:
  // The last values of a quantity, with their times.
  class History {
   public:
    static constexpr int kSize = 64;  // 3 s of 20 Hz hops
    void add(double t, double value) noexcept;
    [[nodiscard]] bool at(double t, double& value) const noexcept;

   private:
    std::array<double, kSize> t_{}, value_{};
    int next_ = 0, size_ = 0;
  };
  void choose() noexcept;

  History revs_, speed_;
  std::array<double, kCandidates> cost_{};
  double delay_ = 0.0;
  double last_t_ = 0.0, last_gps_ = 0.0;  // the fix before
};

}  // namespace gearpulse
