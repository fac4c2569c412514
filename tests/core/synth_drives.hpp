#pragma once
// The drives the synthesis's tests step SpeedSynthesizer through: drives scripted phase by phase at 1 Hz,
// and drives recorded from the simulator (tests/core/data) with the model fitted for each. The car is the
// town drive's hatch (kHatch, kIdle, model_of in tests/town_drive.hpp) unless a test gives its own ladder.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "core/gear_model.hpp"
#include "core/sample.hpp"
#include "core/speed_synth.hpp"
#include "tests/town_drive.hpp"

namespace gearpulse::test {

inline constexpr double kKmh = 1.0 / 3.6;

// A scripted drive at 1 Hz: each phase holds a gear (0 = declutched at idle) and an acceleration.
struct Phase {
  int gear;
  double accel;  // m/s^2
  double seconds;
};
struct Row {
  double t, speed, freq;
  int gear;
};
inline std::vector<Row> script(double v0, const std::vector<Phase>& phases,
                               const std::vector<double>& theta) {
  std::vector<Row> rows;
  double t = 0.0, v = v0;
  for (const Phase& p : phases) {
    for (int k = 0; k < static_cast<int>(p.seconds); ++k) {
      v = std::max(0.0, v + p.accel);
      const double f = p.gear > 0 ? v / theta[static_cast<std::size_t>(p.gear - 1)] : kIdle;
      rows.push_back({t, v, f, p.gear});
      t += 1.0;
    }
  }
  return rows;
}

// Feeds rows with GPS up to `outage_from` (s), engine frequency only afterwards.
inline std::vector<SynthOutput> replay(SpeedSynthesizer& synth, const std::vector<Row>& rows,
                                       double outage_from) {
  std::vector<SynthOutput> out;
  for (const Row& r : rows)
    out.push_back(synth.step(r.t, r.t < outage_from ? r.speed : kMissing, r.freq));
  return out;
}

// The model fitted for a drive recorded from the simulator (tests/core/data/NAME_model.json).
inline std::shared_ptr<GearModel> recorded_model(const std::string& name) {
  std::ifstream model_file(GEARPULSE_SOURCE_DIR "/tests/core/data/" + name + "_model.json");
  std::stringstream model_text;
  model_text << model_file.rdbuf();
  return std::make_shared<GearModel>(parse_model(model_text.str()));
}

// Steps `synth` through a drive recorded from the simulator at RATE ("10hz", "1hz"; tests/core/data/
// NAME_RATE.csv: t, GPS speed or blank, frequency, true speed, and optionally whether the fix is new: 0 for
// a 1 Hz fix held at the tracker's hops until the next, as the daemon gives it), calling check(t, true
// speed, output) after every row. `synth` a SpeedSynthesizer, or a LogReplayer stepping one as `gearpulse
// replay` does a log.
template <class Synth, class Check>
void replay_rows(const std::string& name, const std::string& rate, Synth& synth, Check check) {
  std::ifstream rows(GEARPULSE_SOURCE_DIR "/tests/core/data/" + name + "_" + rate + ".csv");
  REQUIRE(rows);
  std::string line;
  while (std::getline(rows, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> cells(1);
    for (char c : line)
      if (c == ',')
        cells.emplace_back();
      else
        cells.back().push_back(c);
    REQUIRE((cells.size() == 4 || cells.size() == 5));
    const double t = std::stod(cells[0]), freq = std::stod(cells[2]), truth = std::stod(cells[3]);
    const double gps = cells[1].empty() ? kMissing : std::stod(cells[1]);
    const bool gps_new = cells.size() == 4 || cells[4].rfind('0', 0) != 0;  // "0" (or "0\r"): held
    if constexpr (std::is_same_v<Synth, LogReplayer>)
      check(t, truth, synth.step(Sample{t, gps, freq}));
    else
      check(t, truth, synth.step(t, gps, freq, gps_new));
  }
}

// The same through a fresh synthesizer with the model fitted for the drive.
template <class Check>
void replay_recording(const std::string& name, const std::string& rate, Check check) {
  SpeedSynthesizer synth(recorded_model(name));
  replay_rows(name, rate, synth, check);
}

// Replays a recording (replay_recording; 10 Hz unless `rate` says otherwise) and checks the synthesized
// speed against the true one for every row from `from` to `to` s; returns how many rows were checked.
inline int speed_within(const std::string& name, double from, double to, double tolerance,
                        const std::string& rate = "10hz") {
  int checked = 0;
  replay_recording(name, rate, [&](double t, double truth, const SynthOutput& out) {
    if (t < from || t > to) return;
    INFO("t = " << t << " s: truth " << truth * 3.6 << " km/h, synthesized " << out.speed * 3.6 << " in gear "
                << out.gear);
    CHECK(std::abs(out.speed - truth) < tolerance);
    ++checked;
  });
  return checked;
}

}  // namespace gearpulse::test
