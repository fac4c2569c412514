#pragma once
// The daemon's handle on speed synthesis. It lives in its own translation unit so that the pipeline,
// which also sees the device drivers, never includes the synthesis header directly.
#include <cstdint>
#include <memory>

#include "core/gear_model.hpp"

namespace gearpulse::daemon {

enum class Source : std::uint8_t { kNone, kGps, kEngine, kCoast };

[[nodiscard]] const char* to_string(Source source) noexcept;

struct SynthStep {
  double speed = 0.0;  // m/s
  int gear = 0;        // 0 = none/unknown
  Source source = Source::kNone;
};

class Synthesis {
 public:
  Synthesis();
  ~Synthesis();
  Synthesis(const Synthesis&) = delete;
  Synthesis& operator=(const Synthesis&) = delete;

  // Between two steps; no allocation; output stays continuous.
  // False (and the previous model kept) if the synthesizer cannot use it.
  bool set_model(std::shared_ptr<const GearModel> model) noexcept;
  // t: seconds (CLOCK_MONOTONIC), non-decreasing. gps_speed: m/s or NaN without a fresh fix;
  // freq: Hz or NaN when the engine component is not tracked with confidence.
  SynthStep step(double t, double gps_speed, double freq) noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace gearpulse::daemon
