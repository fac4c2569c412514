// `gearpulse fit` and the errors and options both subcommands share, run as the built binary
// (docs/interfaces.md contracts); `gearpulse replay` is cli_replay_test.cpp.
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

TEST_CASE("cli: empty file and missing header are one-line errors with exit 2") {
  TempDir dir;
  write((dir / "empty.csv").string(), "");
  Result r = run(dir, "fit " + (dir / "empty.csv").string());
  CHECK(r.status == 2);
  CHECK(r.err == "gearpulse: " + (dir / "empty.csv").string() + ": empty file\n");
  CHECK(r.out.empty());

  write((dir / "noheader.csv").string(), "0,1.5,40\n1,1.6,41\n");
  r = run(dir, "fit " + (dir / "noheader.csv").string());
  CHECK(r.status == 2);
  CHECK(r.err.find((dir / "noheader.csv").string() + ":1: unrecognised header") != std::string::npos);
  CHECK(lines(r.err) == 1);

  r = run(dir, "fit " + (dir / "missing.csv").string());
  CHECK(r.status == 2);
  CHECK(r.err.find("missing.csv: cannot open") != std::string::npos);
  CHECK(lines(r.err) == 1);

  r = run(dir, "replay --model " + (dir / "missing.json").string() + " " + (dir / "noheader.csv").string());
  CHECK(r.status == 2);
  CHECK(lines(r.err) == 1);
  // A model never fitted is said where one comes from; so is a log given where the model goes.
  CHECK(
      r.err.find("missing.json: cannot open: No such file or directory (fit one first: gearpulse fit --out " +
                 (dir / "missing.json").string() + " LOG...)") != std::string::npos);
  r = run(dir, "replay --model " + (dir / "noheader.csv").string() + " " + (dir / "noheader.csv").string());
  CHECK(r.status == 2);
  CHECK(lines(r.err) == 1);
  CHECK(r.err.find("noheader.csv: model: ") != std::string::npos);
  CHECK(r.err.find("(--model takes the model JSON that gearpulse fit --out writes)") != std::string::npos);
  // And a model where the log goes.
  write((dir / "model.json").string(), "{\n  \"version\": 1,\n  \"gears\": []\n}\n");
  for (const std::string& args :
       {"fit " + (dir / "model.json").string(),
        "replay --model " + (dir / "model.json").string() + " " + (dir / "model.json").string()}) {
    INFO(args);
    r = run(dir, args);
    CHECK(r.status == 2);
    CHECK(r.err == "gearpulse: " + (dir / "model.json").string() +
                       ": a JSON file, not a log (a model from gearpulse fit goes to replay --model)\n");
  }
  // And a recording (a WAV's RIFF header; a log may well begin with an R).
  write((dir / "rec.wav").string(), std::string("RIFF\x24\0\0\0WAVEfmt ", 16));
  r = run(dir, "fit " + (dir / "rec.wav").string());
  CHECK(r.status == 2);
  CHECK(r.err == "gearpulse: " + (dir / "rec.wav").string() +
                     ": a WAV recording, not a log (gearpulse track gives its engine frequency)\n");
  write((dir / "rpm.csv").string(), "RPM,Speed (km/h),Time\n");
  CHECK(run(dir, "fit " + (dir / "rpm.csv").string()).err.find("WAV") == std::string::npos);
}

TEST_CASE("cli: NaN negative and garbage rows are reported with file and line and skipped") {
  TempDir dir;
  std::string text = slurp(simulated_log(dir, 22));
  // Insert bad rows after the header (lines 2..4 of the file).
  const std::size_t header_end = text.find('\n') + 1;
  text.insert(header_end, "0,nan,40\n0,-2,40\n0,abc,40\n");
  write((dir / "bad.csv").string(), text);
  const Result r = run(dir, "fit " + (dir / "bad.csv").string());
  CHECK(r.status == 0);
  CHECK(r.err.find((dir / "bad.csv").string() + ":2: non-finite value") != std::string::npos);
  CHECK(r.err.find((dir / "bad.csv").string() + ":3: negative value") != std::string::npos);
  CHECK(r.err.find((dir / "bad.csv").string() + ":4: not a number") != std::string::npos);
  CHECK(r.err.find("skipped 3 bad rows") != std::string::npos);
  CHECK(nlohmann::json::parse(r.out)["gears"].size() >= 4);

  // Many bad rows: the listing is capped, the count is complete.
  std::string many = "t,speed,freq\n";
  for (int i = 0; i < 100; ++i)
    many += "x,1,2\n";
  many += text.substr(header_end);
  write((dir / "many.csv").string(), many);
  const Result m = run(dir, "fit " + (dir / "many.csv").string());
  CHECK(m.status == 0);
  CHECK(m.err.find("skipped 103 bad rows") != std::string::npos);  // and the three above
  CHECK(lines(m.err) < 20);
}

TEST_CASE("cli: a log with only zero speed or nothing usable is an error") {
  TempDir dir;
  std::string zero = "t,speed,freq\n";
  for (int i = 0; i < 100; ++i)
    zero += std::to_string(i) + ",0," + std::to_string(13.0 + 0.01 * i) + "\n";
  write((dir / "zero.csv").string(), zero);
  Result r = run(dir, "fit " + (dir / "zero.csv").string());
  CHECK(r.status == 2);
  CHECK(r.err.find("zero.csv: nothing to fit") != std::string::npos);
  CHECK(lines(r.err) == 1);

  write((dir / "garbage.csv").string(), "t,speed,freq\nfoo,bar,baz\n\x01\x02\x03\n");
  r = run(dir, "fit " + (dir / "garbage.csv").string());
  CHECK(r.status == 2);
  CHECK(r.err.find("no usable samples") != std::string::npos);
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

TEST_CASE("cli: values beyond any vehicle are bad rows, and replay of extreme values stays well formed") {
  TempDir dir;
  write((dir / "x.csv").string(), "t,speed,freq\n0,1e300,50\n1,10,1e300\n2,10,5e-324\n3,10,40\n");
  const Result fit = run(dir, "fit " + (dir / "x.csv").string());
  CHECK(fit.err.find((dir / "x.csv").string() + ":2: speed") != std::string::npos);
  CHECK(fit.err.find((dir / "x.csv").string() + ":3: frequency") != std::string::npos);
  CHECK(fit.err.find((dir / "x.csv").string() + ":4: frequency") != std::string::npos);
  // The largest speed a row may carry, through replay's formatting.
  const std::string model =
      R"({"version":1,"gears":[{"theta":0.2,"weight":0.5},{"theta":0.4,"weight":0.5}],"sigma_speed":0.1,)"
      R"("sigma_freq":0.2,"samples":100,"log_likelihood":0})";
  write((dir / "m.json").string(), model);
  write((dir / "y.csv").string(), "t,speed,freq\n0,150,50\n1,,50\n");
  const Result replay =
      run(dir, "replay --model " + (dir / "m.json").string() + " " + (dir / "y.csv").string());
  CHECK(replay.status == 0);
  CHECK(lines(replay.out) == 3);
}

TEST_CASE("cli: unknown options and bad values exit 2 with one line") {
  TempDir dir;
  const std::string log = (dir / "x.csv").string();
  write(log, "t,speed,freq\n0,1,10\n");
  for (const std::string& args : {"fit --bogus " + log,
                                  "fit --gears x " + log,
                                  "fit --gears 99 " + log,
                                  "fit --ratios 1.2,abc " + log,
                                  "fit --ratios 0.9 " + log,
                                  "fit --ratios 1e308,1e308 " + log,
                                  "fit --ratios 1.0000001 " + log,
                                  "fit --speed radar " + log,
                                  std::string("fit"),
                                  "replay " + log,
                                  "replay --model " + log + " --frobnicate " + log,
                                  "fit --ratios '' " + log,
                                  "fit --gears 1 " + log,
                                  "frobnicate " + log,
                                  std::string(""),
                                  "fit --row-seconds 0 " + log,
                                  "fit --row-seconds -1 " + log,
                                  "fit --row-seconds nan " + log,
                                  "fit --row-seconds inf " + log,
                                  "fit --row-seconds 2s " + log,
                                  "replay --model " + log + " --row-seconds 3601 " + log,
                                  "replay --model " + log + " --band-low -1 " + log,
                                  "replay --model " + log + " --band-low 50Hz " + log}) {
    INFO(args);
    const Result r = run(dir, args);
    CHECK(r.status == 2);
    CHECK(lines(r.err) == 1);
    CHECK(r.err.rfind("gearpulse: ", 0) == 0);
  }
  // Each names what is wrong: the command, a gear count in the range the fit takes, a row spacing.
  CHECK(run(dir, "frobnicate " + log).err.find("unknown command 'frobnicate'") != std::string::npos);
  CHECK(run(dir, "fit --gears 1 " + log).err.find("from 2 to") != std::string::npos);
  CHECK(run(dir, "fit --row-seconds nan " + log).err.find("--row-seconds: must be a number of seconds") !=
        std::string::npos);
  // A directory where a file belongs is named as one.
  for (const std::string& args :
       {"fit " + dir.path().string(), "replay --model " + dir.path().string() + " " + log}) {
    INFO(args);
    const Result r = run(dir, args);
    CHECK(r.status == 2);
    CHECK(r.err.find("is a directory") != std::string::npos);
  }
  // Logs: the way out is named (the files in it).
  CHECK(run(dir, "fit " + dir.path().string())
            .err.find("is a directory (name the log files in it, as " + (dir / "*.csv").string() + ")") !=
        std::string::npos);
  // No command at all: the commands are listed.
  const Result bare = run(dir, "");
  CHECK(bare.status == 2);
  CHECK(bare.err ==
        "gearpulse: a command is required (commands: fit, replay, track; gearpulse --help says what "
        "each does)\n");
  // A count forgotten before the file: the file name taken for the count is named, not a missing file.
  const Result swallowed = run(dir, "fit --gears " + log);
  CHECK(swallowed.status == 2);
  CHECK(swallowed.err.find("--gears") != std::string::npos);
  CHECK(swallowed.err.find("x.csv") != std::string::npos);
  // A known command missing what it needs is not "unknown".
  const Result missing = run(dir, "replay " + log);
  CHECK(missing.err.find("unknown command") == std::string::npos);
  CHECK(missing.err.find("--model") != std::string::npos);
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

TEST_CASE("cli: output that cannot be written is an error, not a truncated success") {
  TempDir dir;
  const std::string model = fitted_model(dir);
  const std::string log = simulated_log(dir, 24, 300.0);
  for (const std::string& command : {"replay --model " + model + " " + log, "fit " + log}) {
    INFO(command);
    const Result r = run(dir, command + " >/dev/full");
    CHECK(r.status == 2);
    CHECK(r.err.find("cannot write the output to stdout") != std::string::npos);
  }
}

TEST_CASE("cli: --speed on a log that is not a Torque export is said to do nothing") {
  TempDir dir;
  const std::string log = simulated_log(dir, 21);
  const Result r = run(dir, "fit --speed gps " + log);
  CHECK(r.status == 0);
  CHECK(r.err.find("--speed applies to Torque Pro exports, named-column and PID-row logs") !=
        std::string::npos);
  CHECK(run(dir, "fit " + log).err.find("--speed") == std::string::npos);
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
  // The drive without its launches: no first gear, and the few samples of a short log give a rough scale.
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
  CHECK(thin.err.find("the logs likely lack first gear (log some starts from rest)") != std::string::npos);
}

TEST_CASE("cli: each command's --help names the logs it reads and what --speed applies to") {
  TempDir dir;
  for (const char* command : {"fit", "replay"}) {
    INFO(command);
    const Result r = run(dir, std::string(command) + " --help");
    CHECK(r.status == 0);
    CHECK(r.out.find("Torque Pro, named-column and PID-row logs: speed column") != std::string::npos);
  }
  const std::string fit = run(dir, "fit --help").out;
  for (const char* format : {"t,speed,freq", "Torque Pro", "Carloop", "speed,rpm", "SECONDS,PID,VALUE"})
    CHECK(fit.find(format) != std::string::npos);
  CHECK(run(dir, "--help").out.find("track                       Print the") != std::string::npos);
}
