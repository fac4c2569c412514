// Fuzz target for model.json (core/gear_model): parse_model accepts a model that holds the invariants the
// synthesis relies on, or throws std::invalid_argument; what it accepts serialises and parses back equal,
// and drives the synthesizer (which reads extra.*) to finite, non-negative speeds in gears it has.
#include <cmath>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>

#include "core/gear_model.hpp"
#include "core/speed_synth.hpp"
#include "tests/fuzz/fuzz_check.hpp"

using namespace gearpulse;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  GearModel model;
  try {
    model = parse_model(text);
  } catch (const std::invalid_argument&) {
    return 0;
  }
  FUZZ_CHECK(model.gears.size() <= GearModel::kMaxGears);
  for (std::size_t i = 0; i < model.gears.size(); ++i) {
    FUZZ_CHECK(std::isfinite(model.gears[i].theta) && model.gears[i].theta > 0);
    if (i > 0) FUZZ_CHECK(model.gears[i].theta > model.gears[i - 1].theta);
  }
  const std::string written = serialize_model(model);
  GearModel back;
  try {
    back = parse_model(written);
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "a model it accepted does not read back: %s\n%s\n", e.what(), written.c_str());
    std::abort();
  }
  FUZZ_CHECK(back.gears.size() == model.gears.size());
  for (std::size_t i = 0; i < model.gears.size(); ++i) {
    FUZZ_CHECK(back.gears[i].theta == model.gears[i].theta);
    FUZZ_CHECK(back.gears[i].weight == model.gears[i].weight);
    FUZZ_CHECK(back.gears[i].std_error == model.gears[i].std_error);
  }
  FUZZ_CHECK(back.sigma_speed == model.sigma_speed && back.sigma_freq == model.sigma_freq);
  FUZZ_CHECK(back.samples == model.samples);
  FUZZ_CHECK(back.outlier_weight == model.outlier_weight);
  FUZZ_CHECK(back.extra == model.extra);
  FUZZ_CHECK(back.method == model.method && back.reason == model.reason);

  // A short drive, GPS then an outage, through a synthesizer made with the model and one swapped to it.
  const auto shared = std::make_shared<const GearModel>(std::move(model));
  SpeedSynthesizer made(shared);
  SpeedSynthesizer swapped;
  FUZZ_CHECK(swapped.set_model(shared));
  double t = 0.0;
  for (int i = 0; i < 120; ++i, t += 0.5) {
    const double v = i < 20 ? 0.0 : std::min(30.0, 0.8 * (i - 20));
    const double gps = i < 80 ? v : std::nan("");
    const double freq = i < 20 ? 13.0 : 20.0 + std::fmod(0.9 * (i - 20), 40.0);
    for (SpeedSynthesizer* s : {&made, &swapped}) {
      const SynthOutput out = s->step(t, gps, freq);
      FUZZ_CHECK(std::isfinite(out.speed) && out.speed >= 0.0);
      FUZZ_CHECK(out.gear >= 0 && out.gear <= static_cast<int>(shared->gears.size()));
    }
  }
  return 0;
}
