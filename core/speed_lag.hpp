#pragma once
// The speed lag: how late GPS speed is against the engine frequency, the quantity a fit records as the
// model's extra.speed_lag from the pairs it was given and the synthesis takes out of each fix. A receiver
// reports the speed of a moment before it delivers the fix (its own filter, the NMEA sentence, the read:
// 0.2-1 s), and an OBD logger polls speed and revs at different moments of a round. Taken as current, a late
// fix contradicts the gear whose line the revs follow whenever the car gains or loses speed (moving off at 2
// m/s^2, a fix 0.5 s late is 1 m/s slow), and the clutch, whose revs say nothing of the speed, explains both.
//
// Learned from the drive's own fixes by cross-correlation: for each fix faster than kMinSpeed, taken while
// the speed changes by kMinChange a second or more (at a steady speed every candidate fits alike but for
// the revs' noise, which a reading interpolated between two others averages down), and for each candidate
// lag d (0 to kLongestLag in steps of kStep), the revs at t - d (interpolated between those noted) are
// turned into a speed by the nearest gear of the ladder, and the fix's squared log-departure from it,
// bounded by kClip (a shift or a declutch, which no gear explains, counts alike at every lag), is
// averaged with a memory of kMemory fixes. The drive's own lag is the candidate of least average,
// placed between its neighbours by a parabola through the three.
//
// Before the drive shows its own, the lag is the prior: the lag the fit found between the speeds and
// the revs it was given (the model's extra.speed_lag), which is the same quantity measured on the pairs of
// earlier drives. The drive's own lag replaces it only once it is significant: its candidate's average
// is lower than the prior's candidate's by at least kSignificance standard errors of that difference,
// over at least kMinFixes fixes' worth (a fix's departures at two lags are strongly correlated, so the
// difference's own spread, not each average's, is the noise). Where the fixes say little (polled rows
// seconds apart, few changes of speed), the prior stands.
//
// It also keeps the last few seconds of revs and of the filter's own speed, which the synthesis takes a
// fix's lag out with (SpeedSynthesizer::filter_step).
//
// Fixed arrays, no allocation.
#include <array>
#include <span>

namespace gearpulse {

class SpeedLag {
 public:
  // Standard errors by which the drive's lag must beat the prior's (see the header): one-sided, a chance
  // of about 1 in 1000 per candidate that the fixes' noise alone does it, about 1 in 100 over the ten
  // candidates against the prior's.
  static constexpr double kSignificance = 3.0;
  static constexpr double kStep = 0.1;        // s between candidate lags
  static constexpr double kLongestLag = 1.0;  // s: a receiver reports a fix within its period (1 s at 1 Hz)
  static constexpr int kCandidates = 11;      // 0, kStep, ..., kLongestLag
  static constexpr double kMaxGap = 2.5;  // s: revs read further apart do not say what the engine did between

  // Every step: the engine frequency at step time t (Hz; NaN or <= 0: none).
  void note_freq(double t, double freq) noexcept { revs_.add(t, freq); }
  // After every step: the speed the filter holds (its belief's mean) at t.
  void note_speed(double t, double speed) noexcept { speed_.add(t, speed); }
  // The lag believed before the drive's fixes show their own (s, clamped to 0..kLongestLag): the model's
  // extra.speed_lag. May change between any two steps (a retrained model); what was learned is kept.
  void set_prior(double lag) noexcept;
  // Standard errors by which the drive's lag must beat the prior (0: the best candidate is the lag
  // from the first fix that tells the candidates apart, whatever the prior).
  void set_significance(double z) noexcept { significance_ = z; }
  // A new fix: GPS speed `gps` (m/s) stamped t (the step it comes with, or earlier: its caller's stamp;
  // after note_freq for that step); `theta` the ladder's gears ((m/s)/Hz).
  void learn(double t, double gps, std::span<const double> theta) noexcept;
  // s: how much older the speed of a fix is than the revs at its stamp (the step of its row in a log):
  // the drive's own lag once significant, the prior until then.
  [[nodiscard]] double lag() const noexcept { return own_ ? lag_ : prior_; }
  // The drive's fixes have shown a lag significantly better than the prior's.
  [[nodiscard]] bool significant() const noexcept { return own_; }
  // The revs, or the filter's speed, at time t, interpolated between the values noted around it (false,
  // `value` untouched, if no two values kMaxGap apart or closer bracket it, or t is before the oldest kept).
  [[nodiscard]] bool revs_at(double t, double& value) const noexcept { return revs_.at(t, value); }
  [[nodiscard]] bool speed_at(double t, double& value) const noexcept { return speed_.at(t, value); }

 private:
  // The last values of a quantity, with their times.
  class History {
   public:
    // Values closer than kSpacing to the one kept before them replace the newest rather than adding one, so
    // the history spans kSize x kSpacing (8 s) whatever the hop: a fix's lag (up to kLongestLag) plus its
    // age (gps.latency, a few seconds at most) plus the kMaxGap a reading may be interpolated over.
    static constexpr int kSize = 160;
    static constexpr double kSpacing = kStep / 2.0;  // s
    void add(double t, double value) noexcept;
    [[nodiscard]] bool at(double t, double& value) const noexcept;

   private:
    std::array<double, kSize> t_{}, value_{};
    int next_ = 0, size_ = 0;
  };
  void choose() noexcept;

  History revs_, speed_;
  std::array<double, kCandidates> cost_{};  // exponentially weighted sums of each candidate's departures
  // ... and of the products of two candidates' departures (the spread of their difference).
  std::array<std::array<double, kCandidates>, kCandidates> cross_{};
  double weight_ = 0.0, weight_sq_ = 0.0;  // the sums of the weights and of their squares
  double prior_ = 0.0;
  double significance_ = kSignificance;
  double lag_ = 0.0;  // the drive's own (the best candidate, refined)
  bool own_ = false;
  double last_t_ = 0.0, last_gps_ = 0.0;  // the fix before
};

}  // namespace gearpulse
