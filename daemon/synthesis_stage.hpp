#pragma once
// The synthesis step of the live chain: the speed the pulses carry from the tracker's estimate and the
// newest GPS fix, stepped at every hop. The one place the daemon names its synthesizer (the same
// SpeedSynthesizer `gearpulse replay` runs): another synthesizer is put in here.
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

#include "core/speed_synth.hpp"
#include "daemon/model_store.hpp"
#include "drivers/gps_report.hpp"

namespace gearpulse::daemon {

class SynthesisStage {
 public:
  struct Step {
    SynthOutput out;         // speed, gear and source
    bool confident = false;  // the frequency was used: tracked, finite and at least the SNR threshold
  };

  // `band_low` (Hz): the lowest frequency the tracker reads (SynthTuning::reading_floor); 0: any.
  explicit SynthesisStage(double band_low = 0.0) : synth_(nullptr, tuning_of(band_low)) {}

  // The model from the next step on; false when the synthesizer cannot take it (it keeps the previous).
  bool set_model(const ModelPtr& model) noexcept { return synth_.set_model(model); }

  // One step at `t` (s, CLOCK_MONOTONIC; a step never goes back before the last) with the tracker's
  // estimate and the newest fresh GPS fix, if any. Each fix is measured once, however often it is given
  // (gpsd may report one fix more than once); a hop below `min_snr_db` reads as no frequency. A fix is
  // stamped as the training pairs are, its receive time less `gps_latency` (s): the model's speed lag is
  // its lag against that stamp, and the synthesis is told how much older than `t` the stamp is (or newer).
  Step step(double t, double freq, double snr_db, bool tracked, const std::optional<GpsReport>& fix,
            double min_snr_db, double gps_latency = 0.0) noexcept {
    constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
    const double gps_speed = fix ? fix->speed : kNan;
    const bool gps_new = fix && fixes_.is_new(*fix);
    const bool confident = tracked && std::isfinite(freq) && snr_db >= min_snr_db;
    last_t_ = std::max(t, last_t_);
    // Negative when the fix is newer than the window this step's t is the centre of.
    const double age = fix ? last_t_ - (static_cast<double>(fix->rx_ns) * 1e-9 - gps_latency) : 0.0;
    return {synth_.step(last_t_, gps_speed, confident ? freq : kNan, gps_new, age), confident};
  }

  [[nodiscard]] double last_step_time() const noexcept { return last_t_; }
  // Hz, the engine's idle as the synthesis holds it now (SpeedSynthesizer::idle_freq).
  [[nodiscard]] double idle_freq() const noexcept { return synth_.idle_freq(); }

 private:
  static SynthTuning tuning_of(double band_low) noexcept {
    SynthTuning t;
    t.reading_floor = band_low;
    return t;
  }

  SpeedSynthesizer synth_;
  FixNovelty fixes_;
  double last_t_ = 0.0;
};

}  // namespace gearpulse::daemon
