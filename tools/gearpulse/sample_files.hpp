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

}  // namespace gearpulse::cli
