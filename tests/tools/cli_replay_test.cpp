// `gearpulse replay`, run as the built binary (docs/interfaces.md contracts).
#include <stdlib.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include <catch2/catch.hpp>

#include <nlohmann/json.hpp>
#include "tests/test_util.hpp"
#include "tests/tools/cli_run.hpp"

#include "core/gear_model.hpp"
#include "core/sample_io.hpp"
#include "tools/sim/vehicle_sim.hpp"

using gearpulse::test::TempDir;
using namespace gearpulse::test::cli;

TEST_CASE("cli: replay prints t speed gear source for every row") {
  TempDir dir;
  const std::string model = fitted_model(dir);
  const std::string test = simulated_log(dir, 24, 300.0);
  const gearpulse::SampleLog input = read_log(test);
  std::size_t rows = 0, outage_rows = 0, engine_rows = 0;
  for (const std::vector<std::string>& cells : replay(dir, model, test).rows) {
    const auto& s = input.samples.at(rows);
    CHECK(std::stod(cells[0]) == Approx(s.t));
    CHECK(std::stod(cells[1]) >= 0.0);
    CHECK(std::stoi(cells[2]) >= 0);
    const std::string& source = cells[3];
    CHECK((source == "gps" || source == "engine" || source == "coast" || source == "none"));
    if (!s.has_speed()) {
      ++outage_rows;
      CHECK(source != "gps");
      engine_rows += source == "engine";
    } else {
      CHECK(source == "gps");
      CHECK(std::stod(cells[1]) == Approx(s.speed).margin(1e-3));
    }
    ++rows;
  }
  CHECK(rows == input.samples.size());
  CHECK(outage_rows >= 50);
  CHECK(engine_rows > 0);
}

TEST_CASE("cli: replay answers rows whose speed spells no value as outages, and says a header again") {
  TempDir dir;
  const std::string model = fitted_model(dir);
  const std::string original = simulated_log(dir, 24, 300.0);
  const std::size_t samples = read_log(original).samples.size();
  // The outage's empty speed cells written as NA, and the header written again as line 101.
  std::string text = slurp(original);
  for (std::size_t at = text.find(",,"); at != std::string::npos; at = text.find(",,", at))
    text.replace(at, 2, ",NA,");
  std::size_t line_end = 0;
  for (int i = 0; i < 100; ++i)
    line_end = text.find('\n', line_end) + 1;
  text.insert(line_end, "t,speed,freq\n");
  const std::string path = (dir / "spelled.csv").string();
  write(path, text);
  const Replay r = replay(dir, model, path);
  CHECK(r.rows.size() == samples);
  CHECK(std::count_if(r.rows.begin(), r.rows.end(), [](const auto& row) { return row[3] != "gps"; }) >= 50);
  CHECK(r.result.err.find(path + ":101: the header again") != std::string::npos);
}

TEST_CASE(
    "cli: replay answers every row of an OBD log, a repeated row with the output of the row it repeats") {
  TempDir dir;
  const std::string model = fitted_model(dir);
  // A Carloop log: the run-time counter in whole seconds, rpm and speed held between polls, so most rows
  // repeat the row before; one bad row, which is reported and skipped.
  std::string log = "ENGINE_RUN_TINE (), ENGINE_RPM (), VEHICLE_SPEED (), THROTTLE (),\n";
  std::size_t data_rows = 0;
  for (int i = 0; i < 400; ++i) {
    const int refresh = i / 4;  // values change every fourth row
    char row[96];
    std::snprintf(row, sizeof row, "%d.000000, %.6f, %d.000000, 17.6,\n", i / 2,
                  1500.0 + 10.0 * (refresh % 7), 20 + refresh % 5);
    log += row;
    ++data_rows;
    if (i == 200) log += "101.000000, garbage, 3.000000, 17.6,\n";
  }
  write((dir / "carloop.csv").string(), log);
  const Replay r = replay(dir, model, (dir / "carloop.csv").string());
  CHECK(r.result.err.find("carloop.csv:203:") != std::string::npos);
  const auto& rows = r.rows;
  REQUIRE(rows.size() == data_rows);
  for (std::size_t i = 1; i < rows.size(); ++i) {
    CHECK(std::stod(rows[i][0]) >= std::stod(rows[i - 1][0]));
    // Rows 4k+1 .. 4k+3 repeat row 4k: the same answer.
    if (i % 4 != 0) CHECK(rows[i][1] == rows[i - 1][1]);
    if (i % 4 != 0) CHECK(rows[i][3] == rows[i - 1][3]);
  }
}

TEST_CASE(
    "cli: replay answers an outage row that only repeats the held rpm with the output of the row before") {
  TempDir dir;
  const std::string model = fitted_model(dir);
  // An OBD logger's drive as a generic CSV: integer km/h and rpm, each polled once per 1.8 s round and
  // written on every row (every 0.5 s), the speed blanked for a minute. Inside the outage a row whose rpm
  // was not polled again repeats the row before and brings nothing new.
  using namespace gearpulse::sim;
  auto samples = to_samples(simulate_observations(vehicle_preset("hatch-5"), DrivingStyle::kUrban, 400.0, 1,
                                                  25, {.period = 0.5, .obd = true, .seed = 26}));
  for (auto& s : samples)
    if (s.t >= 200.0 && s.t < 260.0) s.speed = gearpulse::kMissing;
  const std::string test = (dir / "obd.csv").string();
  {
    std::ofstream out(test, std::ios::binary);
    gearpulse::write_samples(out, samples);
  }
  const gearpulse::SampleLog input = read_log(test);
  std::vector<std::vector<std::string>> rows = replay(dir, model, test).rows;
  // --band-low 0 is the default: any reading can show the idle.
  CHECK(run(dir, "replay --band-low 0 --model " + model + " " + test).out ==
        run(dir, "replay --model " + model + " " + test).out);
  REQUIRE(rows.size() == input.samples.size());
  for (auto& row : rows)
    row.erase(row.begin());  // speed,gear,source: what the row answers
  // A held copy: the rpm of the row that last brought one, within 3 s of it (an OBD round and a half).
  std::size_t held = 0, fresh = 0, changed = 0;
  double read_freq = -1.0, read_t = 0.0;
  for (std::size_t i = 1; i < rows.size(); ++i) {
    const auto& s = input.samples[i];
    const bool copy = !s.has_speed() && s.has_freq() && s.freq == read_freq && s.t - read_t <= 3.0;
    if (!copy) read_freq = s.freq, read_t = s.t;
    if (s.has_speed() || !s.has_freq()) continue;
    if (copy) {
      ++held;
      CHECK(rows[i] == rows[i - 1]);
    } else {
      ++fresh;
      changed += rows[i] != rows[i - 1];
    }
  }
  CHECK(held >= 40);   // about three of every four rows
  CHECK(fresh >= 20);  // one poll a round
  CHECK(changed >= fresh / 2);
}

TEST_CASE("cli: replay prints t with every digit it was given (epoch seconds keep their fractions)") {
  TempDir dir;
  const std::string model = fitted_model(dir);
  std::string log = "t,speed,freq\n";
  for (int i = 0; i < 50; ++i) {
    char row[96];
    std::snprintf(row, sizeof row, "%.1f,10.0,40.0\n", 1700000000.0 + 0.1 * i);
    log += row;
  }
  write((dir / "epoch.csv").string(), log);
  const Result r = run(dir, "replay --model " + model + " " + (dir / "epoch.csv").string());
  REQUIRE(r.status == 0);
  std::istringstream in(log), out(r.out);
  std::string want, got;
  std::getline(in, want);
  std::getline(out, got);
  std::size_t rows = 0;
  while (std::getline(in, want) && std::getline(out, got)) {
    CHECK(std::stod(got.substr(0, got.find(','))) == std::stod(want.substr(0, want.find(','))));
    ++rows;
  }
  CHECK(rows == 50);
}

TEST_CASE("cli: replay counts a named log's seconds since 1970 from its first in the digits written") {
  TempDir dir;
  const std::string model = fitted_model(dir);
  const std::string path = (dir / "python_obd.csv").string();
  write(path,
        "timestamp,RPM,SPEED (km/h)\n1558525279.922,800,10\n1558525281.521,900,11\n1558525283.12,1000,12\n");
  const Result r = run(dir, "replay --model " + model + " " + path);
  REQUIRE(r.status == 0);
  CHECK(r.out.find("\n1.599,") != std::string::npos);
  CHECK(r.out.find("\n3.198,") != std::string::npos);
}

TEST_CASE("cli: --row-seconds gives the rows of a log without a time column their time, for the synthesis") {
  TempDir dir;
  const std::string model = fitted_model(dir);
  // A drive as speed,rpm rows (km/h and rpm to a tenth) 2 s apart, GPS blanked for 60 s every 180 s, and
  // the same rows as t,speed,freq with their times.
  using namespace gearpulse::sim;
  const auto obs =
      simulate_observations(vehicle_preset("hatch-5"), DrivingStyle::kUrban, 1200.0, 1, 25, {.seed = 125});
  const std::vector<gearpulse::Sample> truth = to_samples(obs);
  std::string rows = "speed,rpm\n", timed = "t,speed,freq\n";
  std::string last;
  std::size_t n = 0;
  for (std::size_t i = 0; i < truth.size(); i += 2) {
    const gearpulse::Sample& s = truth[i];
    const bool outage = std::fmod(s.t, 180.0) >= 120.0;
    if (!std::isfinite(s.freq)) continue;
    const double kmh = std::round(s.speed * 36.0) / 10.0;
    double rpm = std::round(s.freq * 600.0) / 10.0;
    char speed[32] = "", row[64];
    if (s.has_speed() && !outage) std::snprintf(speed, sizeof speed, "%.1f", kmh);
    std::snprintf(row, sizeof row, "%s,%.1f\n", speed, rpm);
    if (row == last) {  // a row repeating the one before is a held OBD value, dropped by the reader
      rpm += 0.1;
      std::snprintf(row, sizeof row, "%s,%.1f\n", speed, rpm);
    }
    last = row;
    rows += row;
    char line[128];
    if (speed[0] != '\0')
      std::snprintf(line, sizeof line, "%zu,%.17g,%.17g\n", 2 * n, kmh * (1.0 / 3.6), rpm / 60.0);
    else
      std::snprintf(line, sizeof line, "%zu,,%.17g\n", 2 * n, rpm / 60.0);
    timed += line;
    ++n;
  }
  const std::string rows_log = (dir / "rows.csv").string(), timed_log = (dir / "timed.csv").string();
  write(rows_log, rows);
  write(timed_log, timed);
  const Result at_two = run(dir, "replay --model " + model + " --row-seconds 2 " + rows_log);
  const Result with_times = run(dir, "replay --model " + model + " " + timed_log);
  const Result at_one = run(dir, "replay --model " + model + " " + rows_log);
  REQUIRE(at_two.status == 0);
  REQUIRE(with_times.status == 0);
  REQUIRE(at_one.status == 0);
  CHECK(lines(at_two.out) == n + 1);
  CHECK(at_two.out == with_times.out);  // t and every synthesized speed, gear and source
  CHECK(at_one.out != with_times.out);
  CHECK(at_two.err.find("no time column") == std::string::npos);
  CHECK(at_two.err.find("note: " + rows_log +
                        ": column 'speed' names no unit: read as km/h (pass --speed-unit mph or m/s, "
                        "or name it 'speed (mph)', if it is not)") != std::string::npos);
  CHECK(with_times.err.find("names no unit") == std::string::npos);
  CHECK(at_one.err.find("no time column") != std::string::npos);
  CHECK(at_one.err.find("--row-seconds") != std::string::npos);
  // A log with its own times is said to be untouched by it; fit takes it as replay does.
  const Result on_timed = run(dir, "fit --row-seconds 2 " + timed_log);
  CHECK(on_timed.status == 0);
  CHECK(on_timed.err.find("--row-seconds applies to logs without a time column") != std::string::npos);
  CHECK(on_timed.out == run(dir, "fit " + timed_log).out);
  const Result fit_rows = run(dir, "fit --row-seconds 2 " + rows_log);
  CHECK(fit_rows.status == 0);
  CHECK(fit_rows.err.find("warning") == std::string::npos);
  CHECK(fit_rows.err.find("no time column") == std::string::npos);
  CHECK(nlohmann::json::parse(fit_rows.out)["gears"].size() >= 4);
}

TEST_CASE("cli: a log whose header and time start again is fitted and replayed as a second drive") {
  TempDir dir;
  const std::string model = fitted_model(dir);
  const std::string first = simulated_log(dir, 24, 300.0), second = simulated_log(dir, 25, 500.0);
  const std::string restarted = (dir / "restarted.csv").string();
  write(restarted, slurp(first) + slurp(second));
  // The same drives in one file without the restart: the second's times written already put on.
  const gearpulse::SampleLog a = read_log(first);
  gearpulse::SampleLog b = read_log(second);
  const double on = a.samples.back().t + gearpulse::kRestartGap - b.samples.front().t;
  for (gearpulse::Sample& s : b.samples)
    s.t += on;
  std::vector<gearpulse::Sample> both = a.samples;
  both.insert(both.end(), b.samples.begin(), b.samples.end());
  const std::string joined = (dir / "joined.csv").string();
  {
    std::ofstream out(joined, std::ios::binary);
    gearpulse::write_samples(out, both);
  }

  const Result fit = run(dir, "fit " + restarted), halves = run(dir, "fit " + first + " " + second);
  REQUIRE(fit.status == 0);
  REQUIRE(halves.status == 0);
  CHECK(fit.out == halves.out);
  const std::string said = restarted + ": 1 logger restart (the time from the start again";
  CHECK(fit.err.find(said) != std::string::npos);
  CHECK(fit.err.find(said, fit.err.find(said) + 1) == std::string::npos);  // once, not per row
  CHECK(fit.err.find("time goes backwards") == std::string::npos);

  const Replay r = replay(dir, model, restarted), j = replay(dir, model, joined),
               one = replay(dir, model, first);
  REQUIRE(r.rows.size() == both.size());
  CHECK(r.rows == j.rows);
  REQUIRE(one.rows.size() == a.samples.size());
  CHECK(std::equal(one.rows.begin(), one.rows.end(), r.rows.begin()));
  CHECK(std::count_if(r.rows.begin() + static_cast<std::ptrdiff_t>(one.rows.size()), r.rows.end(),
                      [](const auto& row) { return row[3] == "engine"; }) > 0);
  CHECK(r.result.err.find(restarted + ":" + std::to_string(lines(slurp(first)) + 1) + ": the header again") !=
        std::string::npos);
}

TEST_CASE("cli: a second drive appended without its header is fitted and replayed as a second drive") {
  TempDir dir;
  const std::string model = fitted_model(dir);
  const std::string first = simulated_log(dir, 24, 300.0), second = simulated_log(dir, 25, 500.0);
  const std::string text = slurp(second);
  const std::string appended = (dir / "appended.csv").string();
  write(appended, slurp(first) + text.substr(text.find('\n') + 1));  // its times from 0 again, no header
  const Result fit = run(dir, "fit " + appended), halves = run(dir, "fit " + first + " " + second);
  REQUIRE(fit.status == 0);
  REQUIRE(halves.status == 0);
  CHECK(fit.out == halves.out);
  const std::string said = appended + ": 1 logger restart (the time from the start again";
  CHECK(fit.err.find(said) != std::string::npos);
  CHECK(fit.err.find(said, fit.err.find(said) + 1) == std::string::npos);  // once, not per row
  CHECK(fit.err.find("time goes backwards") == std::string::npos);
  const Replay r = replay(dir, model, appended), one = replay(dir, model, first);
  REQUIRE(r.rows.size() == read_log(first).samples.size() + read_log(second).samples.size());
  CHECK(std::equal(one.rows.begin(), one.rows.end(), r.rows.begin()));
}

TEST_CASE("cli: replay says when the log has no outage to bridge or the model no gears to bridge it with") {
  TempDir dir;
  const std::string model = fitted_model(dir);
  const std::string whole = simulated_log(dir, 24), with_outage = simulated_log(dir, 25, 300.0);
  const Result r = run(dir, "replay --model " + model + " " + whole);
  CHECK(r.status == 0);
  CHECK(r.err.find("note: " + whole + " has a speed in every row: no GPS outage to bridge") !=
        std::string::npos);
  CHECK(r.out.find(",engine\n") == std::string::npos);
  const Result outage = run(dir, "replay --model " + model + " " + with_outage);
  CHECK(outage.status == 0);
  CHECK(outage.err.find("note:") == std::string::npos);
  // A model of an automatic (no ladder) bridges nothing: said, with its reason.
  write((dir / "none.json").string(),
        R"({"version": 1, "gears": [], "fitted": false, "reason": "one cluster"})");
  const Result no_gears = run(dir, "replay --model " + (dir / "none.json").string() + " " + with_outage);
  CHECK(no_gears.status == 0);
  CHECK(
      no_gears.err.find("none.json has no gears (one cluster): in an outage the speed is not taken from the "
                        "engine") != std::string::npos);
}
