// Fuzz target for the speed synthesis (core/speed_synth): a stream of steps (time steps, GPS speed or none,
// frequency or none, fixes given again, resets, model swaps, jumps of time), with NaN, infinities, negative
// and huge values among them, through models fitted on simulated drives, a bare model and none. Every
// output is a finite speed >= 0 in a gear the model has, and the belief stays finite.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "core/gear_model.hpp"
#include "core/speed_synth.hpp"
#include "tests/fuzz/fuzz_check.hpp"

using namespace gearpulse;

namespace {

std::vector<std::shared_ptr<const GearModel>> g_models;

// Reads the fuzz bytes as values: mostly ordinary ones, now and then special.
struct Bytes {
  const std::uint8_t* p;
  std::size_t n;
  [[nodiscard]] bool empty() const { return n == 0; }
  std::uint8_t byte() {
    if (n == 0) return 0;
    --n;
    return *p++;
  }
  double raw() {
    std::uint8_t b[8] = {};
    for (auto& x : b)
      x = byte();
    double d = 0.0;
    std::memcpy(&d, b, sizeof d);
    return d;
  }
  double value(double scale) {
    constexpr double kInf = std::numeric_limits<double>::infinity();
    switch (byte() % 16) {
      case 0:
        return std::numeric_limits<double>::quiet_NaN();
      case 1:
        return kInf;
      case 2:
        return -kInf;
      case 3:
        return -scale * (byte() / 255.0);
      case 4:
        return 1e308;
      case 5:
        return -1e308;
      case 6:
        return std::numeric_limits<double>::denorm_min();
      case 7:
        return raw();
      case 8:
        return 0.0;
      default:
        return scale * (byte() + 256.0 * byte()) / 65535.0;
    }
  }
};

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  for (const char* name :
       {"fast_shifter", "skip_shift", "launch_declutch", "launch_pull", "creep_after_launch",
        "obd_cruise_fourth", "moveoff_seven_speed", "braking_downshifts"}) {
    std::ifstream in(std::string(GEARPULSE_SOURCE_DIR "/tests/core/data/") + name + "_model.json");
    std::stringstream text;
    text << in.rdbuf();
    g_models.push_back(std::make_shared<const GearModel>(parse_model(text.str())));
  }
  auto bare = std::make_shared<GearModel>();  // no extra: every habit at its default
  bare->gears = {{0.2, 0.5, 0.001}, {0.4, 0.5, 0.001}};
  bare->sigma_speed = 0.5;
  bare->sigma_freq = 1.0;
  g_models.push_back(std::move(bare));
  g_models.push_back(nullptr);  // no model
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Bytes in{data, size};
  SpeedSynthesizer synth(g_models[in.byte() % g_models.size()]);
  double t = in.byte() % 4 == 0 ? in.value(1e6) : 0.0;
  for (int steps = 0; !in.empty() && steps < 5000;) {
    const std::uint8_t flags = in.byte();
    if ((flags & 0xF0) == 0xF0) {
      switch (flags & 3) {
        case 0:
          synth.reset();
          break;
        case 1:
          synth.set_model(g_models[in.byte() % g_models.size()]);
          break;
        case 2:
          t = in.value(1e9);
          break;
        default:
          break;
      }
      continue;
    }
    t += (flags & 1) != 0 ? in.value(5.0) : 0.1 * (in.byte() % 21);
    const double gps = (flags & 2) != 0 ? in.value((flags & 8) != 0 ? 60.0 : 300.0) : std::nan("");
    const double freq = (flags & 4) != 0 ? in.value((flags & 16) != 0 ? 200.0 : 30000.0) : std::nan("");
    const SynthOutput out = synth.step(t, gps, freq, (flags & 32) == 0);
    ++steps;
    const GearModel* model = synth.model().get();
    const int gears = model != nullptr ? static_cast<int>(model->gears.size()) : 0;
    FUZZ_CHECK(std::isfinite(out.speed) && out.speed >= 0.0);
    FUZZ_CHECK(out.gear >= 0 && out.gear <= gears);
    double total = synth.mode_probability(0);
    for (int j = 1; j <= gears; ++j) {
      const double p = synth.mode_probability(j);
      FUZZ_CHECK(std::isfinite(p) && p >= 0.0);
      total += p;
    }
    FUZZ_CHECK(std::isfinite(total));
  }
  return 0;
}
