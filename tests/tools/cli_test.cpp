// `gearpulse fit`, run as the built binary (docs/interfaces.md contracts); the errors and options it shares
// with `gearpulse replay` are cli_errors_test.cpp, `gearpulse replay` cli_replay_test.cpp.
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

namespace fs = std::filesystem;
using gearpulse::test::TempDir;
using namespace gearpulse::test::cli;

namespace {

// A drive's rows (speed and rpm both read) as a speed,rpm log whose logger converts the OBD speed (whole
// km/h) to mph writes them.
std::string converted_mph_log(const gearpulse::SampleLog& drive) {
  std::string log = "t,speed,rpm\n";
  for (const gearpulse::Sample& s : drive.samples) {
    if (!s.has_speed() || !s.has_freq()) continue;
    char row[96];
    std::snprintf(row, sizeof row, "%.3f,%.6f,%.2f\n", s.t, std::round(s.speed * 3.6) / 1.609344,
                  s.freq * 60.0);
    log += row;
  }
  return log;
}

}  // namespace

TEST_CASE("cli: fit prints the model JSON of docs/interfaces.md and writes --out and --plot") {
  TempDir dir;
  const std::string log = simulated_log(dir, 21);
  const Result r = run(dir, "fit --out " + (dir / "model.json").string() + " --plot " +
                                (dir / "fit.svg").string() + " " + log);
  REQUIRE(r.status == 0);
  const auto json = nlohmann::json::parse(r.out);
  CHECK(json["version"] == 1);
  REQUIRE(json["gears"].is_array());
  CHECK(json["gears"].size() >= 4);
  double previous = 0.0;
  for (const auto& g : json["gears"]) {
    CHECK(g["theta"].get<double>() > previous);
    previous = g["theta"].get<double>();
    CHECK(g.contains("weight"));
    CHECK(g.contains("stderr"));
  }
  for (const char* key : {"sigma_speed", "sigma_freq", "samples", "log_likelihood"})
    CHECK(json.contains(key));
  CHECK(json["fitted"] == true);
  CHECK(json["samples"].get<long>() > 500);
  CHECK(slurp((dir / "model.json").string()) == r.out);
  const std::string svg = slurp((dir / "fit.svg").string());
  CHECK(svg.rfind("<svg", 0) == 0);
  CHECK(svg.find("</svg>") != std::string::npos);
  CHECK(svg.find("<polyline") != std::string::npos);  // the fitted density
  CHECK(svg.find("<rect x=") != std::string::npos);   // histogram bars
}

TEST_CASE("cli: a one-gear log gives a valid model and never a made-up ladder") {
  TempDir dir;
  std::string text = "t,speed,freq\n";
  for (int i = 0; i < 600; ++i) {
    const double f = 30.0 + 10.0 * std::sin(i / 40.0) + 0.1 * ((i * 7919) % 13 - 6);
    text += std::to_string(i) + "," + std::to_string(0.35 * f) + "," + std::to_string(f) + "\n";
  }
  write((dir / "one.csv").string(), text);
  const Result r = run(dir, "fit " + (dir / "one.csv").string());
  CHECK(r.status == 0);
  const auto json = nlohmann::json::parse(r.out);
  REQUIRE(json["gears"].is_array());
  CHECK(json["gears"].size() <= 1);
  if (json["gears"].empty()) {
    CHECK(r.err.find("no gear ladder") != std::string::npos);
  } else {
    CHECK(json["gears"][0]["theta"].get<double>() == Approx(0.35).epsilon(0.01));
  }
}

TEST_CASE("cli: logs no gearbox made give no ladder, with the reason") {
  TempDir dir;
  struct Case {
    const char* name;
    const char* reason;
    std::function<std::string(int)> row;  // t,speed,freq of row i
  };
  const std::vector<Case> cases = {
      // the engine held at one speed while the road speed cycles
      {"const_freq", "engine frequency hardly changes",
       [](int i) { return std::to_string(i) + "," + std::to_string(5 + (i / 5) % 10) + ",30"; }},
      // one road speed while the engine frequency cycles
      {"const_speed", "speed hardly changes",
       [](int i) { return std::to_string(i) + ",12," + std::to_string(20 + (i / 5) % 10); }},
      // every row at one instant
      {"const_t", "same time stamp",
       [](int i) { return "0," + std::to_string(5 + i % 10) + "," + std::to_string(20 + (i * 7) % 23); }},
      // speed and frequency that do not belong together: the ratio never holds between rows
      {"unrelated", "hardly ever holds",
       [](int i) {
         return std::to_string(i) + "," + std::to_string(2 + (i * 7919) % 30) + "," +
                std::to_string(15 + (i * 104729) % 40);
       }},
  };
  for (const Case& c : cases) {
    INFO(c.name);
    std::string text = "t,speed,freq\n";
    for (int i = 0; i < 600; ++i)
      text += c.row(i) + "\n";
    write((dir / (std::string(c.name) + ".csv")).string(), text);
    const Result r = run(dir, "fit " + (dir / (std::string(c.name) + ".csv")).string());
    CHECK(r.status == 0);
    const auto json = nlohmann::json::parse(r.out);
    CHECK(json["gears"].empty());
    CHECK(json.value("reason", "").find(c.reason) != std::string::npos);
    // Said on stderr with what it means for the user's car.
    CHECK(
        r.err.find(
            "gearpulse: no gear ladder: " + json.value("reason", "") +
            "; an automatic or CVT has none (no speed from the engine in outages), a manual car's logs show "
            "one with more driving in each gear") != std::string::npos);
    // No mixture was fitted: its figures keep the contract's type (numbers, 0), `fitted` says they are not
    // estimates, and the model loads.
    for (const char* key : {"sigma_speed", "sigma_freq", "log_likelihood", "outlier_weight"})
      CHECK(json.at(key).is_number());
    CHECK(json.at("fitted") == false);
    CHECK(json["samples"].get<long>() > 0);
    CHECK(gearpulse::parse_model(r.out).empty());
  }
}

TEST_CASE("cli: fit writes nothing to stdout when --out cannot be written, and names gears forced apart") {
  TempDir dir;
  const std::string log = simulated_log(dir, 21);
  // --out or --plot naming a log given would replace the drive: refused, the log untouched.
  const std::string before = slurp(log);
  for (const std::string& args : {"fit --out " + log + " " + log, "fit --plot " + log + " " + log}) {
    INFO(args);
    const Result r = run(dir, args);
    CHECK(r.status == 2);
    CHECK(r.out.empty());
    CHECK(r.err.find(" is one of the logs given (" + log + "): it would be replaced; name another file") !=
          std::string::npos);
  }
  CHECK(slurp(log) == before);
  // --out and --plot naming one file (here spelt two ways): the plot would replace the model.
  const std::string same = (dir / "same.out").string();
  const Result both =
      run(dir, "fit --out " + same + " --plot " + (dir / "." / "same.out").string() + " " + log);
  CHECK(both.status == 2);
  CHECK(both.err.find("name the same file: the plot would replace the model; name two files") !=
        std::string::npos);
  CHECK_FALSE(std::filesystem::exists(same));
  const Result bad = run(dir, "fit --out " + (dir / "missing/model.json").string() + " " + log);
  CHECK(bad.status == 2);
  CHECK(bad.out.empty());
  CHECK(bad.err.find("missing/model.json: cannot write: No such file or directory") != std::string::npos);
  // Asked for more gears than the car has, the fit splits one: a warning names the pair.
  const auto fitted = nlohmann::json::parse(run(dir, "fit " + log).out);
  const std::size_t gears = fitted["gears"].size();
  REQUIRE(gears >= 4);
  CHECK(run(dir, "fit " + log).err.find("warning") == std::string::npos);
  const Result forced = run(dir, "fit --gears " + std::to_string(gears + 1) + " " + log);
  CHECK(forced.status == 0);
  CHECK(forced.err.find("warning: gears") != std::string::npos);
  CHECK(run(dir, "fit --gears " + std::to_string(gears) + " " + log).err.find("warning") ==
        std::string::npos);
  // Fewer than the car has: the larger ladder the data supports is named.
  const Result fewer = run(dir, "fit --gears " + std::to_string(gears - 1) + " " + log);
  CHECK(fewer.status == 0);
  CHECK(fewer.err.find("warning: the data does not show " + std::to_string(gears - 1) + " gears: " +
                       std::to_string(gears) + " gears explain the data better") != std::string::npos);
  CHECK(nlohmann::json::parse(fewer.out)["extra"]["forced_doubt"]["gears"] == gears);
  // Paper mode fits as many gears as its ratios say: priors that ask for more than the car has are named
  // the same way.
  const Result priors = run(dir, "fit --ratios 1.3,1.3,1.3,1.3,1.3,1.3,1.3 " + log);
  CHECK(priors.status == 0);
  CHECK(priors.err.find("warning: gears") != std::string::npos);
  CHECK(priors.err.find("--ratios") != std::string::npos);
}

TEST_CASE("cli: fit --out follows a symbolic link and writes into a FIFO rather than replace either") {
  TempDir dir;
  const std::string log = simulated_log(dir, 21);
  const std::string json = run(dir, "fit " + log).out;
  REQUIRE_FALSE(json.empty());
  write((dir / "model.json").string(), "{}");
  std::filesystem::create_symlink("model.json", (dir / "current.json").string());
  REQUIRE(run(dir, "fit --out " + (dir / "current.json").string() + " " + log).status == 0);
  CHECK(std::filesystem::is_symlink((dir / "current.json").string()));
  CHECK(slurp((dir / "model.json").string()) == json);
  REQUIRE(mkfifo((dir / "pipe").string().c_str(), 0600) == 0);
  // A reader on the FIFO, as `gearpulse fit --out /dev/stdout | ...` has one.
  const std::string got = (dir / "from-pipe.json").string();
  const std::string reader = "cat '" + (dir / "pipe").string() + "' > '" + got + "' &";
  REQUIRE(std::system(reader.c_str()) == 0);
  CHECK(run(dir, "fit --out " + (dir / "pipe").string() + " " + log).status == 0);
  for (int i = 0; i < 500 && slurp(got) != json; ++i)  // 10 s for cat, a process a loaded machine runs late
    usleep(20000);
  CHECK(std::filesystem::is_fifo((dir / "pipe").string()));
  CHECK(slurp(got) == json);
  // /dev/stdout into a pipe: its link in /proc names no path ("pipe:[N]"); written to, not replaced.
  const Result to_stdout = run(dir, "fit --out /dev/stdout " + log);
  CHECK(to_stdout.status == 0);
  CHECK(to_stdout.err.find("cannot write") == std::string::npos);
  CHECK(to_stdout.out == json + json);
  const Result into_dir = run(dir, "fit --out " + dir.path().string() + " " + log);
  CHECK(into_dir.status == 2);
  CHECK(into_dir.err.find("is a directory") != std::string::npos);
}

TEST_CASE("cli: fit --out replaces a model in place: its permissions kept, no temporary file left") {
  TempDir dir;
  const std::string log = simulated_log(dir, 22);
  const std::string json = run(dir, "fit " + log).out;
  REQUIRE_FALSE(json.empty());
  // A model readable by its owner only stays so when a fit replaces it.
  write((dir / "model.json").string(), "{}");
  REQUIRE(::chmod((dir / "model.json").string().c_str(), 0600) == 0);
  REQUIRE(run(dir, "fit --out " + (dir / "model.json").string() + " " + log).status == 0);
  CHECK(slurp((dir / "model.json").string()) == json);
  struct stat st {};
  REQUIRE(::stat((dir / "model.json").string().c_str(), &st) == 0);
  CHECK((st.st_mode & 0777) == 0600);
  for (const auto& entry : std::filesystem::directory_iterator(dir.path()))
    CHECK(entry.path().filename().string().find(".tmp") == std::string::npos);
}

TEST_CASE("cli: fit of a Torque export with GPS and OBD speed reads the gears from the wheel speed") {
  const std::string log =
      (gearpulse::test::real_data_dir() / "torque-louisville/rpms_chart_from_obd.csv").string();
  if (!fs::exists(log)) GEARPULSE_SKIP_TEST("real logs not found under " << gearpulse::test::real_data_dir());
  TempDir dir;
  const Result both = run(dir, "fit " + log);
  REQUIRE(both.status == 0);
  const auto model = nlohmann::json::parse(both.out);
  CHECK(model["gears"].size() == 5);
  CHECK(model["extra"]["speed_scale"]["from"] == "wheel");
  CHECK(both.err.find("OBD wheel speed") != std::string::npos);
  // --speed gps is the GPS speed alone, as before.
  const Result gps = run(dir, "fit --speed gps " + log);
  REQUIRE(gps.status == 0);
  CHECK_FALSE(nlohmann::json::parse(gps.out)["extra"].contains("speed_scale"));
  CHECK(gps.err.find("OBD wheel speed") == std::string::npos);
}

TEST_CASE("cli: fit says on stderr how many gears it found, on how much driving, and what to log") {
  TempDir dir;
  const std::string log = simulated_log(dir, 21);
  const Result r = run(dir, "fit " + log);
  REQUIRE(r.status == 0);
  const auto model = nlohmann::json::parse(r.out);
  const std::size_t gears = model["gears"].size();
  REQUIRE(gears >= 4);
  CHECK(r.err.find("gearpulse: " + std::to_string(gears) + " gears, fitted on " +
                   std::to_string(model["samples"].get<long>()) + " samples") != std::string::npos);
  for (std::size_t g = 1; g <= gears; ++g)
    CHECK(r.err.find("  gear " + std::to_string(g) + ": theta ") != std::string::npos);
  CHECK(r.err.find("samples in gear, mostly at ") != std::string::npos);
  CHECK(r.err.find("if the car has more than " + std::to_string(gears) + " forward gears") !=
        std::string::npos);
  // A generic log's freq need not be rpm / 60: no km/h per 1000 rpm. A speed,rpm log's is.
  CHECK(r.err.find("km/h per 1000 rpm") == std::string::npos);
  const gearpulse::SampleLog samples = read_log(log);
  std::string rpm_log = "t,speed,rpm\n";
  for (const gearpulse::Sample& s : samples.samples) {
    char row[96];
    if (s.has_speed() && s.has_freq()) {
      std::snprintf(row, sizeof row, "%.3f,%.3f,%.2f\n", s.t, s.speed * 3.6, s.freq * 60.0);
      rpm_log += row;
    }
  }
  write((dir / "rpm.csv").string(), rpm_log);
  const Result rpm = run(dir, "fit " + (dir / "rpm.csv").string());
  REQUIRE(rpm.status == 0);
  const double top = nlohmann::json::parse(rpm.out)["gears"].back()["theta"].get<double>();
  char per_1000[32];
  std::snprintf(per_1000, sizeof per_1000, "%.1f km/h per 1000 rpm", top * 60.0);  // (m/s)/Hz -> km/h/krpm
  CHECK(rpm.err.find(per_1000) != std::string::npos);
  CHECK(rpm.err.find("names no unit: read as km/h") != std::string::npos);  // speeds to the metre per hour
  // The same drive as a logger that converts the OBD speed (whole km/h) to mph writes it: read in mph, said.
  write((dir / "mph.csv").string(), converted_mph_log(samples));
  const Result mph = run(dir, "fit " + (dir / "mph.csv").string());
  REQUIRE(mph.status == 0);
  CHECK(mph.err.find("every value is a whole km/h in mph (an OBD speed converted): read as mph") !=
        std::string::npos);
  CHECK(nlohmann::json::parse(mph.out)["gears"].back()["theta"].get<double>() == Approx(top).epsilon(0.02));
  // The drive without its launches: no first gear.
  std::string no_launch = "t,speed,freq\n";
  for (const gearpulse::Sample& s : samples.samples) {
    char row[96];
    if (s.has_speed() && s.has_freq() && (s.speed == 0.0 || s.speed > 9.0) && s.t < 600.0) {
      std::snprintf(row, sizeof row, "%.3f,%.4f,%.4f\n", s.t, s.speed, s.freq);
      no_launch += row;
    }
  }
  write((dir / "no_launch.csv").string(), no_launch);
  const Result thin = run(dir, "fit " + (dir / "no_launch.csv").string());
  REQUIRE(thin.status == 0);
  CHECK(
      thin.err.find("km/h at idle, more than a car's first gear does (a motorcycle's or a tall one may): if "
                    "there is a lower gear, log some starts from rest\n") != std::string::npos);
  // The drive with a GPS's speed noise (+-0.3 m/s): first gear, seen briefly and slowly, where that noise is
  // largest against the speed, is known to worse than kRoughGear (kGearWindow / 3, 0.967 %); every gear
  // whose +- passes that threshold is marked, and the advice line prints it.
  std::string noisy = "t,speed,freq\n";
  for (std::size_t i = 0; i < samples.samples.size(); ++i) {
    const gearpulse::Sample& s = samples.samples[i];
    const double jitter = 0.3 * (static_cast<double>(i % 3) - 1.0);
    char row[96];
    std::snprintf(row, sizeof row, "%.3f,%.4f,%.4f\n", s.t,
                  s.speed > 0.0 ? std::max(0.01, s.speed + jitter) : 0.0, s.freq);
    noisy += row;
  }
  write((dir / "noisy.csv").string(), noisy);
  const Result rough = run(dir, "fit " + (dir / "noisy.csv").string());
  REQUIRE(rough.status == 0);
  INFO(rough.err);
  CHECK(rough.err.find(" (rough)\n") != std::string::npos);
  CHECK(
      rough.err.find("  a rough gear's scale is known to worse than 0.97 %: log more driving in that gear") !=
      std::string::npos);
  std::istringstream summary(rough.err);
  for (std::string line; std::getline(summary, line);) {
    const std::size_t pm = line.find("+- ");
    if (line.rfind("  gear ", 0) != 0 || pm == std::string::npos) continue;
    INFO(line);
    const double error_pct = std::stod(line.substr(pm + 3));
    CHECK((line.find("(rough)") != std::string::npos) == (error_pct >= 0.97));
  }
}

TEST_CASE("cli: fit --speed-unit reads a speed column that names no unit as a header naming it would") {
  TempDir dir;
  const gearpulse::SampleLog samples = read_log(simulated_log(dir, 21));
  // The drive in mph, as a data set's SPEED column and as SPEED (mph); and as a speed,rpm log's whole km/h
  // written in mph, which reads as mph unless told km/h.
  std::string bare = "time,ENGINE_RPM,SPEED\n", named = "time,ENGINE_RPM,SPEED (mph)\n";
  for (const gearpulse::Sample& s : samples.samples) {
    if (!s.has_speed() || !s.has_freq()) continue;
    char row[96];
    std::snprintf(row, sizeof row, "%.3f,%.2f,%.3f\n", s.t, s.freq * 60.0, s.speed / 0.44704);
    bare += row;
    named += row;
  }
  write((dir / "bare.csv").string(), bare);
  write((dir / "named.csv").string(), named);
  write((dir / "converted.csv").string(), converted_mph_log(samples));
  const Result given = run(dir, "fit --speed-unit mph " + (dir / "bare.csv").string());
  const Result stated = run(dir, "fit " + (dir / "named.csv").string());
  REQUIRE(given.status == 0);
  REQUIRE(stated.status == 0);
  CHECK(nlohmann::json::parse(given.out)["gears"].size() >= 4);
  CHECK(given.out == stated.out);  // the same ladder, to the last digit
  CHECK(run(dir, "fit " + (dir / "bare.csv").string()).status == 2);
  const Result as_mph = run(dir, "fit " + (dir / "converted.csv").string());
  const Result as_kmh = run(dir, "fit --speed-unit km/h " + (dir / "converted.csv").string());
  REQUIRE(as_mph.status == 0);
  REQUIRE(as_kmh.status == 0);
  CHECK(as_mph.err.find("read as mph") != std::string::npos);
  CHECK(as_kmh.err.find("names no unit") == std::string::npos);  // told, not guessed: no note
  const auto top = [](const Result& r) {
    return nlohmann::json::parse(r.out)["gears"].back()["theta"].get<double>();
  };
  CHECK(top(as_kmh) == Approx(top(as_mph) / 1.609344).epsilon(0.01));
}

TEST_CASE("cli: a Torque export fitted from a FIFO is read once, its ladder from the GPS speed") {
  // The wheel speed is read in a second pass over the file, which a FIFO cannot give: opening it again
  // waited for a writer that had gone.
  const std::filesystem::path torque = GEARPULSE_REAL_DATA_DIR "/torque-louisville/rpms_chart_from_obd.csv";
  if (!std::filesystem::exists(torque)) GEARPULSE_SKIP_TEST("no real logs at " GEARPULSE_REAL_DATA_DIR);
  TempDir dir;
  const std::string fifo = (dir / "log.fifo").string();
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  const std::string err = (dir / "stderr.txt").string();
  const gearpulse::test::ShellResult r = gearpulse::test::run_shell(
      "(cat '" + torque.string() + "' > " + fifo + " &); timeout 20 " + kCli + " fit " + fifo + " 2>" + err);
  CHECK(r.status == 0);
  CHECK(slurp(err).find("is not a regular file: a Torque export's wheel speed is read in a second pass") !=
        std::string::npos);
  CHECK(nlohmann::json::parse(r.out)["gears"].size() >= 4);
}
