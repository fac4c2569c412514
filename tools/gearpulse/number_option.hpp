#pragma once
// A check for a numeric option: a finite number (a whole one where asked) within [lo, hi], said in one
// message whatever is wrong ("abc", "nan", "1.5" for a channel, a value out of range). CLI11's Range says
// "not in range" of a value that is no number, and lets NaN through.
#include <cmath>
#include <cstdlib>
#include <string>

#include <CLI/CLI.hpp>

namespace gearpulse::cli {

inline CLI::Validator number_in(double lo, double hi, bool whole = false) {
  return CLI::Validator(
      [lo, hi, whole](std::string& text) {
        char* end = nullptr;
        const double v = std::strtod(text.c_str(), &end);
        if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(v) || v < lo || v > hi ||
            (whole && v != std::floor(v)))
          return std::string("must be ") + (whole ? "a whole number" : "a number") + " from " +
                 CLI::detail::to_string(lo) + " to " + CLI::detail::to_string(hi) + ", not '" + text + "'";
        return std::string();
      },
      whole ? "INT" : "NUM");
}

}  // namespace gearpulse::cli
