#include "tools/gearpulse/sample_files.hpp"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <string_view>

#include <CLI/CLI.hpp>

#include "core/log_reading.hpp"
#include "tools/gearpulse/commands.hpp"

namespace gearpulse::cli {
namespace {

constexpr std::size_t kMaxPrintedSkips = 10;  // per file; the rest are only counted

}  // namespace

TorqueSpeed parse_torque_speed(const std::string& text) {
  if (text == "auto") return TorqueSpeed::kAuto;
  if (text == "gps") return TorqueSpeed::kGps;
  if (text == "obd") return TorqueSpeed::kObd;
  throw UsageError("--speed must be auto, gps or obd, not '" + text + "'");
}

void add_row_seconds_option(CLI::App& sub, std::optional<double>& row_seconds) {
  constexpr double kMaxRowSeconds = 3600.0;
  sub.add_option("--row-seconds", row_seconds,
                 "Logs without a time column (speed,rpm): seconds between rows, the unit of the row counter "
                 "(default 1)")
      ->check(CLI::Validator(
          [](std::string& text) {
            char* end = nullptr;
            const double v = std::strtod(text.c_str(), &end);
            if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(v) || v <= 0.0 ||
                v > kMaxRowSeconds)
              return "must be a number of seconds above 0 and at most " +
                     std::to_string(static_cast<int>(kMaxRowSeconds)) + ", not '" + text + "'";
            return std::string();
          },
          "SEC"));
}

void add_speed_unit_option(CLI::App& sub, std::optional<std::string>& speed_unit) {
  sub.add_option("--speed-unit", speed_unit,
                 "Unit of a speed column whose name states none (named columns, speed,rpm): km/h, mph, m/s "
                 "or knots; a column that states its unit keeps it, t,speed,freq's is m/s")
      ->check(CLI::Validator(
          [](std::string& text) {
            return speed_unit_named(text) ? std::string()
                                          : "must be km/h, mph, m/s or knots, not '" + text + "'";
          },
          "UNIT"));
}

void warn_row_seconds(const std::vector<SampleLog>& logs, bool given, bool note_default) {
  for (const SampleLog& log : logs) {
    if (given && !log.time_from_rows)
      std::fprintf(stderr,
                   "gearpulse: warning: %s: --row-seconds applies to logs without a time column; this %s "
                   "log has its own times\n",
                   log.name.c_str(), std::string(format_name(log.format)).c_str());
    if (!given && note_default && log.time_from_rows)
      std::fprintf(stderr,
                   "gearpulse: note: %s has no time column: its rows are taken 1 s apart (--row-seconds "
                   "sets how far)\n",
                   log.name.c_str());
  }
}

std::vector<SampleLog> read_sample_files(const std::vector<std::string>& paths, const ReadOptions& options) {
  std::vector<SampleLog> logs;
  for (const std::string& path : paths) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec))
      throw UsageError(path + ": is a directory (name the log files in it, as " +
                       (std::filesystem::path(path) / "*.csv").string() + ")");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw UsageError(path + ": cannot open: " + std::strerror(errno));
    // A model where a log belongs (`fit model.json`, the model and the log swapped): JSON opens with '{',
    // which no log's header does. Peeked, not read: a pipe (`<(zcat log.gz)`) cannot seek back.
    if (in.peek() == '{')
      throw UsageError(path + ": a JSON file, not a log (a model from gearpulse fit goes to replay --model)");
    // A recording where a log belongs: a WAV opens with "RIFF", a size and "WAVE" (an AVI or a WebP is a RIFF
    // file too, and left to the reader's message). Read from a second handle, on a regular file only, for the
    // same reason.
    if (std::filesystem::is_regular_file(path, ec)) {
      char magic[12] = {};
      if (std::ifstream probe(path, std::ios::binary); probe.read(magic, sizeof magic) &&
                                                       std::string_view(magic, 4) == "RIFF" &&
                                                       std::string_view(magic + 8, 4) == "WAVE")
        throw UsageError(path + ": a WAV recording, not a log (gearpulse track gives its engine frequency)");
    }
    try {
      logs.push_back(read_samples(in, path, options));
    } catch (const SampleFileError& e) {
      throw UsageError(e.what());
    }
    const SampleLog& log = logs.back();
    if (options.torque_speed != TorqueSpeed::kAuto && log.format != SampleFileFormat::kTorque &&
        log.format != SampleFileFormat::kColumns && log.format != SampleFileFormat::kPidRows)
      std::fprintf(
          stderr,
          "gearpulse: warning: %s: --speed applies to Torque Pro exports, named-column and PID-row logs; "
          "this %s log has one speed\n",
          path.c_str(), std::string(format_name(log.format)).c_str());
    // --speed-unit names the unit of a speed column that states none: a log whose speed has a unit of its
    // own keeps it, said when the two differ (the column's name or units row is the log's word, the flag
    // may be meant for another file).
    const bool named = log.format == SampleFileFormat::kColumns || log.format == SampleFileFormat::kSpeedRpm;
    if (options.speed_unit && !named)
      std::fprintf(
          stderr,
          "gearpulse: warning: %s: --speed-unit applies to named-column and speed,rpm logs whose "
          "speed column names no unit; this %s log's speed is in its format's unit or the one it states\n",
          path.c_str(), std::string(format_name(log.format)).c_str());
    else if (options.speed_unit && log.speed_unit != options.speed_unit->name)
      std::fprintf(stderr,
                   "gearpulse: warning: %s: --speed-unit %s, but column '%s' states %s%s%s: read as %s\n",
                   path.c_str(), std::string(options.speed_unit->name).c_str(), log.speed_column.c_str(),
                   log.speed_unit.c_str(), log.speed_unit_stated_in.empty() ? "" : " in ",
                   log.speed_unit_stated_in.c_str(), log.speed_unit.c_str());
    // Without it, a speed,rpm log's speed column names no unit and is read as km/h, or as mph or m/s when
    // its values are whole km/h in that unit (docs/interfaces.md): a log in another unit would fit a ladder
    // off by 1.6 or 3.6 without a word, so the reading is said with its way out.
    const bool told = log.format == SampleFileFormat::kSpeedRpm && !options.speed_unit;
    if (told && log.speed_unit == "km/h")
      std::fprintf(stderr,
                   "gearpulse: note: %s: column '%s' names no unit: read as km/h (pass --speed-unit mph or "
                   "m/s, or name it '%s (mph)', if it is not)\n",
                   path.c_str(), log.speed_column.c_str(), log.speed_column.c_str());
    else if (told)
      std::fprintf(stderr,
                   "gearpulse: note: %s: column '%s' names no unit, but every value is a whole km/h in %s "
                   "(an OBD speed converted): read as %s (pass --speed-unit km/h, or name it '%s (km/h)', if "
                   "it is not)\n",
                   path.c_str(), log.speed_column.c_str(), log.speed_unit.c_str(), log.speed_unit.c_str(),
                   log.speed_column.c_str());
    for (const std::string& warning : log.warnings)
      std::fprintf(stderr, "gearpulse: warning: %s\n", warning.c_str());
    if (log.restarts > 0)
      std::fprintf(
          stderr,
          "gearpulse: %s: %zu logger restart%s (the time from the start again, after the header again or "
          "falling back over %.0f s): each read as a new drive, %.0f s after the rows before it\n",
          path.c_str(), log.restarts, log.restarts == 1 ? "" : "s", kClockReset, kRestartGap);
    for (std::size_t i = 0; i < log.skipped.size() && i < kMaxPrintedSkips; ++i)
      std::fprintf(stderr, "%s\n", log.skipped[i].c_str());
    if (log.skipped_count > 0) {
      std::fprintf(stderr, "gearpulse: %s: skipped %zu bad row%s (%zu shown)\n", path.c_str(),
                   log.skipped_count, log.skipped_count == 1 ? "" : "s",
                   std::min(log.skipped_count, kMaxPrintedSkips));
    }
  }
  return logs;
}

std::vector<SampleLog> read_wheel_speeds(const std::vector<std::string>& paths,
                                         const std::vector<SampleLog>& logs) {
  std::vector<SampleLog> wheel;
  if (paths.size() != logs.size()) return {};
  for (std::size_t i = 0; i < logs.size(); ++i) {
    if (logs[i].format != SampleFileFormat::kTorque || !log_reading::torque_gps_column(logs[i].speed_column))
      return {};
    // The file is read a second time: a FIFO or a pipe cannot be (opening a FIFO again waits for a writer
    // that has gone), so its ladder is read from the GPS speed.
    std::error_code ec;
    if (!std::filesystem::is_regular_file(paths[i], ec)) {
      std::fprintf(stderr,
                   "gearpulse: note: %s is not a regular file: a Torque export's wheel speed is read in a "
                   "second pass, which a pipe cannot give; the ladder is read from its GPS speed\n",
                   paths[i].c_str());
      return {};
    }
    std::ifstream in(paths[i], std::ios::binary);
    std::optional<SampleLog> w = in ? read_wheel_speed(in, logs[i]) : std::nullopt;
    if (!w) return {};  // GPS alone
    wheel.push_back(std::move(*w));
  }
  return wheel;
}

}  // namespace gearpulse::cli
