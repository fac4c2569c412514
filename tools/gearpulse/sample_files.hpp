#pragma once
// Reading sample logs named on the command line, for `fit` and `replay`: opens the files, parses them with
// core/sample_io and reports skipped rows on stderr ("file:line: reason", capped, then a count).
#include <optional>
#include <string>
#include <vector>

#include "core/sample_io.hpp"

namespace CLI {
class App;
}  // namespace CLI

namespace gearpulse::cli {

// Parses "auto", "gps" or "obd" (the --speed option); throws UsageError otherwise.
[[nodiscard]] TorqueSpeed parse_torque_speed(const std::string& text);

// Adds --row-seconds (ReadOptions::row_seconds: seconds between the rows of a log without a time column)
// to a subcommand, checked as it is parsed: finite, above 0, at most an hour. Unset when not given.
void add_row_seconds_option(CLI::App& sub, std::optional<double>& row_seconds);

// Adds --speed-unit (ReadOptions::speed_unit: the unit of a speed column whose name states none) to a
// subcommand, checked as it is parsed: km/h, mph, m/s or knots. Unset when not given.
void add_speed_unit_option(CLI::App& sub, std::optional<std::string>& speed_unit);

// Says on stderr when --row-seconds was given for a log with a time column of its own (it does nothing
// there) and, with `note_default`, when a log without one is read at the default 1 s per row.
void warn_row_seconds(const std::vector<SampleLog>& logs, bool given, bool note_default);

// Throws UsageError (one line, naming the file) if a file cannot be opened or holds nothing usable.
[[nodiscard]] std::vector<SampleLog> read_sample_files(const std::vector<std::string>& paths,
                                                       const ReadOptions& options);

// The OBD wheel speed of Torque Pro exports whose speed was read from GPS (--speed auto), one log per path,
// rows as `logs`: empty unless every log is such an export with an OBD speed column too. Bad rows were
// reported by the first reading and are not again.
[[nodiscard]] std::vector<SampleLog> read_wheel_speeds(const std::vector<std::string>& paths,
                                                       const std::vector<SampleLog>& logs);

}  // namespace gearpulse::cli
