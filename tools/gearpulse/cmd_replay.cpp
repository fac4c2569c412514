// `gearpulse replay`: runs the daemon's speed synthesis over a sample log as if live and prints
// t,speed,gear,source for every row the reader accepts (docs/interfaces.md). Rows with an empty speed are GPS
// outages.
#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>

#include <CLI/CLI.hpp>

#include "core/gear_model.hpp"
#include "core/speed_synth.hpp"
#include "tools/gearpulse/commands.hpp"
#include "tools/gearpulse/number_option.hpp"
#include "tools/gearpulse/sample_files.hpp"

namespace gearpulse::cli {
namespace {

struct ReplayCommand {
  std::string model;
  std::string speed = "auto";
  std::optional<double> row_seconds;      // --row-seconds, unset when not given (the reader's default)
  std::optional<std::string> speed_unit;  // --speed-unit, unset when not given
  double band_low = 0.0;  // --band-low: the lowest frequency the log's readings can show (0: any)
  std::string file;
};

std::shared_ptr<const GearModel> load_model(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw UsageError(path + ": is a directory");
  // A model never fitted, or a log given where the model goes: the error says where a model comes from.
  constexpr const char* kFromFit = " (--model takes the model JSON that gearpulse fit --out writes)";
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    const int error = errno;
    throw UsageError(path + ": cannot open: " + std::strerror(error) +
                     (error == ENOENT ? " (fit one first: gearpulse fit --out " + path + " LOG...)" : ""));
  }
  std::stringstream text;
  text << in.rdbuf();
  try {
    return std::make_shared<const GearModel>(parse_model(text.str()));
  } catch (const std::invalid_argument& e) {
    throw UsageError(path + ": " + e.what() + kFromFit);
  }
}

int run_replay(const ReplayCommand& cmd) {
  const auto model = load_model(cmd.model);
  ReadOptions read;
  read.torque_speed = parse_torque_speed(cmd.speed);
  read.keep_rows = true;
  if (cmd.row_seconds) read.row_seconds = *cmd.row_seconds;
  if (cmd.speed_unit) read.speed_unit = speed_unit_named(*cmd.speed_unit);
  std::vector<SampleLog> logs = read_sample_files({cmd.file}, read);
  warn_row_seconds(logs, cmd.row_seconds.has_value(), true);
  const SampleLog log = std::move(logs.front());
  // A first replay is often of a whole drive with its GPS speed in every row: it prints that speed back,
  // and the user is told how to see the engine's, as a model without gears is said to give none.
  if (std::all_of(log.samples.begin(), log.samples.end(), [](const Sample& s) { return s.has_speed(); }))
    std::fprintf(stderr,
                 "gearpulse: note: %s has a speed in every row: no GPS outage to bridge, so every row is "
                 "'gps'; empty the speed cells of a stretch to see the speed from the engine there\n",
                 log.name.c_str());
  if (model->gears.empty())
    std::fprintf(
        stderr,
        "gearpulse: note: %s has no gears (%s): in an outage the speed is not taken from the "
        "engine\n",
        cmd.model.c_str(),
        model->reason.empty() ? "no gear ladder in the data it was fitted on" : model->reason.c_str());

  // One output row per accepted input row: a sample steps the synthesis once, at its first row; an OBD
  // row repeating held values answers with the output of the sample it repeats, and so does a sample
  // without speed that only repeats the held rpm (repeats_held_freq).
  SynthTuning tuning;
  tuning.reading_floor = cmd.band_low;  // as the daemon's tracker.band_low
  SpeedSynthesizer synth(model, tuning);
  LogReplayer replayer(synth);
  std::string out = "t,speed,gear,source\n";
  SynthOutput o;
  std::size_t stepped = 0;  // samples stepped so far
  char t[32];               // the shortest text of any double fits
  char row[512];            // room for any double in %.4f (at most 309 digits before the point)
  for (const InputRow& r : log.rows) {
    for (; stepped <= r.sample; ++stepped)
      o = replayer.step(log.samples[stepped]);
    // t as the shortest text that reads back to the same double (epoch seconds keep their fractions).
    const int t_len = static_cast<int>(std::to_chars(t, t + sizeof t, r.t).ptr - t);
    const std::string_view source = source_name(o.source);
    const int n = std::snprintf(row, sizeof row, "%.*s,%.4f,%d,%.*s\n", t_len, t, o.speed, o.gear,
                                static_cast<int>(source.size()), source.data());
    out.append(row, std::min(static_cast<std::size_t>(std::max(n, 0)), sizeof row - 1));
    if (out.size() > (1u << 16)) {
      std::fwrite(out.data(), 1, out.size(), stdout);
      out.clear();
    }
  }
  std::fwrite(out.data(), 1, out.size(), stdout);
  std::fflush(stdout);
  return 0;
}

}  // namespace

void add_replay(CLI::App& app, int& status) {
  auto cmd = std::make_shared<ReplayCommand>();
  CLI::App* sub = app.add_subcommand(
      "replay", "Run the speed synthesis over a sample log as if live; print t,speed,gear,source");
  sub->add_option("--model", cmd->model, "Model JSON (from gearpulse fit --out)")->required();
  sub->add_option(
         "--speed", cmd->speed,
         "Torque Pro, named-column and PID-row logs: speed column to use, auto (GPS if any), gps or obd")
      ->capture_default_str();
  add_row_seconds_option(*sub, cmd->row_seconds);
  add_speed_unit_option(*sub, cmd->speed_unit);
  sub->add_option("--band-low", cmd->band_low,
                  "Hz: the lowest frequency the log's readings can show, as the daemon's tracker.band_low "
                  "(0: any; a log of gearpulsed's tracker readings: its band's low end)")
      ->check(number_in(0.0, 10000.0))
      ->capture_default_str();
  sub->add_option("file", cmd->file, "Sample log, as fit reads; rows with an empty speed are GPS outages")
      ->required();
  sub->callback([cmd, &status] { status = run_replay(*cmd); });
}

}  // namespace gearpulse::cli
