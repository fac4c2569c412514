#pragma once
// Reading sample logs named on the command line, for `fit` and `replay`: opens the files, parses them with
// core/sample_io and reports skipped rows on stderr ("file:line: reason", capped, then a count).
#include <string>
#include <vector>

#include "core/sample_io.hpp"

namespace gearpulse::cli {

// Parses "auto", "gps" or "obd" (the --speed option); throws UsageError otherwise.
[[nodiscard]] TorqueSpeed parse_torque_speed(const std::string& text);

// Throws UsageError (one line, naming the file) if a file cannot be opened or holds nothing usable.
[[nodiscard]] std::vector<SampleLog> read_sample_files(const std::vector<std::string>& paths,
                                                       const ReadOptions& options);

// The OBD wheel speed of Torque Pro exports whose speed was read from GPS (--speed auto), one log per path,
// rows as `logs`: empty unless every log is such an export with an OBD speed column too. Bad rows were
// reported by the first reading and are not again.
[[nodiscard]] std::vector<SampleLog> read_wheel_speeds(const std::vector<std::string>& paths,
                                                       const std::vector<SampleLog>& logs);

}  // namespace gearpulse::cli
