#pragma once
// A log given as text, read as a file named log.csv would be: the samples, or the reader's error message.
#include <sstream>
#include <string>

#include "core/sample_io.hpp"

namespace gearpulse::test {

inline SampleLog read_log_text(const std::string& text, const ReadOptions& options = {}) {
  std::istringstream in(text);
  return read_samples(in, "log.csv", options);
}

inline std::string error_of(const std::string& text) {
  try {
    (void)read_log_text(text);
  } catch (const SampleFileError& e) {
    return e.what();
  }
  return "(no error)";
}

}  // namespace gearpulse::test
