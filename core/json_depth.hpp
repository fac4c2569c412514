#pragma once
// How deeply a JSON text nests its arrays and objects, counted without parsing it. nlohmann::json parses
// without recursion, but copies, compares and prints a value recursively: a small file nested a hundred
// thousand deep overflows the stack in a copy, and a few tens of kilobytes nested deep print as gigabytes
// of indentation. Readers check the depth first and refuse such a text as malformed.
#include <cstddef>
#include <string_view>

namespace gearpulse {

// The deepest nesting of '[' and '{' outside strings (0 for a bare number or string). Counts brackets only:
// whether the text is valid JSON is the parser's to say.
[[nodiscard]] constexpr std::size_t json_nesting(std::string_view text) noexcept {
  std::size_t depth = 0, deepest = 0;
  bool in_string = false, escaped = false;
  for (const char c : text) {
    if (in_string) {
      if (escaped)
        escaped = false;
      else if (c == '\\')
        escaped = true;
      else if (c == '"')
        in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > deepest) deepest = depth;
    } else if ((c == ']' || c == '}') && depth > 0) {
      --depth;
    }
  }
  return deepest;
}

}  // namespace gearpulse
