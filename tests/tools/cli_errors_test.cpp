// The errors and options `gearpulse fit` and `gearpulse replay` share (unreadable logs, bad rows, unknown
// options, output that cannot be written, --speed, --help), run as the built binary (docs/interfaces.md
// contracts); `gearpulse fit` is cli_test.cpp, `gearpulse replay` cli_replay_test.cpp.
#include <cstddef>
#include <string>

#include <catch2/catch.hpp>

#include <nlohmann/json.hpp>
#include "tests/test_util.hpp"
#include "tests/tools/cli_run.hpp"

using gearpulse::test::TempDir;
using namespace gearpulse::test::cli;

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

  // A file without line breaks (binary data, a device) is not read whole into one line.
  write((dir / "long.csv").string(), "t,speed,freq\n" + std::string(std::size_t{17} << 20, '7'));
  r = run(dir, "fit " + (dir / "long.csv").string());
  CHECK(r.status == 2);
  CHECK(r.err == "gearpulse: " + (dir / "long.csv").string() +
                     ":2: a line longer than 16 MiB: not a log of text rows\n");

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
  // Another RIFF file (an AVI: "RIFF", its size, "AVI ") is no WAV: the reader's own message.
  write((dir / "clip.avi").string(), std::string("RIFF\x24\0\0\0AVI LIST", 16));
  r = run(dir, "fit " + (dir / "clip.avi").string());
  CHECK(r.status == 2);
  CHECK(r.err.find("WAV") == std::string::npos);
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
                                  "fit --speed-unit kph " + log,
                                  "replay --model " + log + " --speed-unit MPH " + log,
                                  "replay --model " + log + " --band-low -1 " + log,
                                  "replay --model " + log + " --band-low 50Hz " + log,
                                  "replay --model " + log + " --band-low nan " + log,
                                  "track --channel abc " + log,
                                  "track --channel 1.5 " + log,
                                  "track --decision-lag nan " + log}) {
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
  CHECK(run(dir, "fit --speed-unit kph " + log).err ==
        "gearpulse: --speed-unit: must be km/h, mph, m/s or knots, not 'kph'\n");
  CHECK(run(dir, "replay --model " + log + " --band-low nan " + log).err ==
        "gearpulse: --band-low: must be a number from 0 to 10000, not 'nan'\n");
  CHECK(run(dir, "track --channel abc " + log).err ==
        "gearpulse: --channel: must be a whole number from 0 to 1023, not 'abc'\n");
  // A directory where a file belongs is named as one.
  for (const std::string& args :
       {"fit " + dir.path().string(), "replay --model " + dir.path().string() + " " + log,
        "track " + dir.path().string()}) {
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

// `gearpulse fit ... | head` whose reader has gone: exit 2 and the message, as for a full disk, not a death
// by SIGPIPE that a script sees as 141.
TEST_CASE("cli: output into a pipe nobody reads is an error, not a death by SIGPIPE") {
  TempDir dir;
  const std::string log = simulated_log(dir, 24, 300.0);
  const int status = gearpulse::test::run_into_closed_pipe({kCli, "fit", log}, dir / "err.txt");
  CHECK(status == 2);
  CHECK(gearpulse::test::read_text(dir / "err.txt").find("cannot write the output to stdout") !=
        std::string::npos);
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

TEST_CASE("cli: --speed-unit reads a speed column that names no unit, one that names its own keeps it") {
  TempDir dir;
  const std::string model = fitted_model(dir);
  const std::string bare = (dir / "bare.csv").string(), stated = (dir / "stated.csv").string();
  const std::string rows = "0,800,0\n1,1500,10\n2,2100,20\n";
  write(bare, "time,ENGINE_RPM,SPEED\n" + rows);
  write(stated, "time,ENGINE_RPM,SPEED (km/h)\n" + rows);
  // Refused without it, the way out named; read with it, in fit and replay.
  const Result refused = run(dir, "fit " + bare);
  CHECK(refused.status == 2);
  CHECK(refused.err ==
        "gearpulse: " + bare +
            ":1: speed column 'SPEED' states no unit: name it with km/h, mph, m/s or knots, or "
            "pass --speed-unit\n");
  const Result mph = run(dir, "replay --model " + model + " --speed-unit mph " + bare);
  REQUIRE(mph.status == 0);
  CHECK(mph.out.find("\n2,8.9408,") != std::string::npos);  // 20 mph
  CHECK(mph.err.find("--speed-unit") == std::string::npos);
  // A column that states km/h stays km/h, said once with the column and both units.
  const Result plain = run(dir, "replay --model " + model + " " + stated);
  const Result against = run(dir, "replay --model " + model + " --speed-unit mph " + stated);
  REQUIRE(against.status == 0);
  CHECK(against.out == plain.out);
  CHECK(against.out.find("\n2,5.5556,") != std::string::npos);  // 20 km/h
  const std::string warning = "gearpulse: warning: " + stated +
                              ": --speed-unit mph, but column 'SPEED (km/h)' states km/h: read as km/h\n";
  CHECK(against.err.find(warning) != std::string::npos);
  CHECK(against.err.find(warning, against.err.find(warning) + 1) == std::string::npos);
  // A unit stated in the cells or a units row is said as such, with the column's own name.
  const std::string cells = (dir / "cells.csv").string(), units_row = (dir / "units_row.csv").string();
  write(cells,
        "time,ENGINE_RPM,SPEED\n0,800,0 kilometer_per_hour\n1,1500,10 kilometer_per_hour\n2,2100,20 "
        "kilometer_per_hour\n");
  write(units_row, "time,ENGINE_RPM,SPEED\ns,rpm,km/h\n" + rows);
  for (const auto& [path, where] :
       {std::pair{cells, "in its cells"}, std::pair{units_row, "in its units row"}}) {
    const Result r = run(dir, "replay --model " + model + " --speed-unit mph " + path);
    REQUIRE(r.status == 0);
    CHECK(r.out.find("\n2,5.5556,") != std::string::npos);  // 20 km/h
    CHECK(r.err.find("gearpulse: warning: " + path + ": --speed-unit mph, but column 'SPEED' states km/h " +
                     where + ": read as km/h\n") != std::string::npos);
  }
  // docs/interfaces.md quotes the warning (its lines wrapped).
  std::string doc;
  for (const char c : slurp(std::string(GEARPULSE_SOURCE_DIR) + "/docs/interfaces.md"))
    if (c != '\n' && (c != ' ' || (!doc.empty() && doc.back() != ' '))) doc += c;
  CHECK(doc.find("`--speed-unit mph, but column 'SPEED' states km/h in its cells: read as km/h`") !=
        std::string::npos);
  // The generic log's speed is m/s by contract: said to be untouched.
  const std::string generic = simulated_log(dir, 21);
  const Result on_generic = run(dir, "fit --speed-unit km/h " + generic);
  CHECK(on_generic.status == 0);
  CHECK(on_generic.out == run(dir, "fit " + generic).out);
  CHECK(on_generic.err.find("--speed-unit applies to named-column and speed,rpm logs") != std::string::npos);
}

TEST_CASE("cli: each command's --help names the logs it reads and what --speed and --speed-unit apply to") {
  TempDir dir;
  for (const char* command : {"fit", "replay"}) {
    INFO(command);
    const Result r = run(dir, std::string(command) + " --help");
    CHECK(r.status == 0);
    CHECK(r.out.find("Torque Pro, named-column and PID-row logs: speed column") != std::string::npos);
    CHECK(r.out.find("--speed-unit") != std::string::npos);
    CHECK(r.out.find("whose name states none (named columns, speed,rpm): km/h, mph, m/s or knots") !=
          std::string::npos);
  }
  const std::string fit = run(dir, "fit --help").out;
  for (const char* format : {"t,speed,freq", "Torque Pro", "Carloop", "speed,rpm", "SECONDS,PID,VALUE"})
    CHECK(fit.find(format) != std::string::npos);
  CHECK(run(dir, "--help").out.find("track                       Print the") != std::string::npos);
}
