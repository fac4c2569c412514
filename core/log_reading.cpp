#include "core/log_reading.hpp"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>

namespace gearpulse::log_reading {

std::string_view trim(std::string_view s) noexcept {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front())))
    s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back())))
    s.remove_suffix(1);
  if (s.size() >= 2 && s.front() == '"' && s.back() == '"') s = trim(s.substr(1, s.size() - 2));
  return s;
}

namespace {

// Where the cell starting at `start` ends if it opens with a double quote (after spaces) that closes on the
// line: just past its closing quote, for a delimiter inside it is text ("Speed, km/h"); else `start`. A quote
// that never closes clears `quotes` (the rest of the line is split as if unquoted: each cell is then scanned
// once, and a line of a million quotes costs a million steps, not a million per cell).
std::size_t quoted_cell_end(std::string_view line, std::size_t start, char delimiter, bool& quotes) noexcept {
  std::size_t at = start;
  while (at < line.size() && line[at] != delimiter && std::isspace(static_cast<unsigned char>(line[at])))
    ++at;
  if (!quotes || at == line.size() || line[at] != '"') return start;
  for (std::size_t close = line.find('"', at + 1); close != std::string_view::npos;
       close = line.find('"', close + 2)) {
    if (close + 1 == line.size() || line[close + 1] != '"') return close + 1;  // "" is a quote inside
  }
  quotes = false;  // a stray quote, not a quoted cell
  return start;
}

}  // namespace

bool split_cells(std::string_view line, std::vector<std::string_view>& cells, std::size_t limit,
                 char delimiter) {
  cells.clear();
  std::size_t start = 0;
  bool quotes = true;
  while (cells.size() < limit) {
    const std::size_t comma = line.find(delimiter, quoted_cell_end(line, start, delimiter, quotes));
    if (comma == std::string_view::npos) {
      cells.push_back(trim(line.substr(start)));
      return true;
    }
    cells.push_back(trim(line.substr(start, comma - start)));
    start = comma + 1;
  }
  return false;
}

std::string quoted(std::string_view cell) {
  constexpr std::size_t kMaxShown = 24;
  std::string out = "'";
  for (char c : cell.substr(0, kMaxShown))
    out += std::isprint(static_cast<unsigned char>(c)) ? c : '?';
  if (cell.size() > kMaxShown) out += "...";
  return out + "'";
}

namespace {

bool same_letters(std::string_view a, std::string_view b) noexcept {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) == std::tolower(static_cast<unsigned char>(y));
         });
}

bool spells_missing(std::string_view text) noexcept {
  return text.empty() || text == "-" || text.front() == '#' || same_letters(text, "NA") ||
         same_letters(text, "N/A") || same_letters(text, "null") || same_letters(text, "None");
}

}  // namespace

Cell parse_cell(std::string_view text, std::string_view column) {
  Cell cell;
  if (spells_missing(text)) return cell;
  double value = 0.0;
  const bool plus = text.starts_with('+');  // "+3.5", as some loggers write a signed value
  const std::string_view number = plus ? text.substr(1) : text;
  const auto [ptr, ec] = std::from_chars(number.data(), number.data() + number.size(), value);
  if (ec != std::errc() || ptr != number.data() + number.size() || (plus && number.starts_with('-'))) {
    cell.kind = CellKind::kBad;
    cell.problem = (ec == std::errc::result_out_of_range && ptr == number.data() + number.size()
                        ? "a number beyond what a double holds in column "
                        : "not a number in column ") +
                   std::string(column) + ": " + quoted(text);
    return cell;
  }
  if (!std::isfinite(value)) {
    cell.kind = CellKind::kBad;
    cell.problem = "non-finite value in column " + std::string(column) + ": " + quoted(text);
    if (std::isnan(value)) cell.problem += " (an empty cell is a missing value)";
    return cell;
  }
  // A log's clock stays far below this, even in milliseconds since 1970 (read, and warned about as a
  // generic log's rows far apart); a time beyond it is a corrupt cell (1e308 overflowed the Carloop
  // reader's fit of its row times).
  constexpr double kMaxTime = 1e13;
  if ((column == "t" || column == "time") && std::abs(value) > kMaxTime) {
    cell.kind = CellKind::kBad;
    cell.problem = "time beyond any log's clock in column " + std::string(column) + ": " + quoted(text);
    return cell;
  }
  if (value < 0.0 && column != "t") {
    cell.kind = CellKind::kBad;
    cell.problem = "negative value in column " + std::string(column) + ": " + quoted(text);
    return cell;
  }
  cell.kind = CellKind::kNumber;
  cell.value = value;
  return cell;
}

namespace {

// Whether `s` is decimal digits (or hexadecimal ones) and nothing else.
bool digits(std::string_view s, bool hex = false) noexcept {
  return !s.empty() && std::all_of(s.begin(), s.end(), [hex](char c) {
    return (c >= '0' && c <= '9') || (hex && ((c >= 'a' && c <= 'f') || (c >= 'A' && c <= 'F')));
  });
}

// Whether `text` is digit groups (DigitGroups) separated by `sep`, perhaps with a decimal part after `mark`
// (the other of point and comma); `plain` is the number without them, its decimal mark a point, and
// `groups` the count of separators.
bool digit_groups(std::string_view text, char sep, char mark, std::string& plain, std::size_t& groups) {
  std::string_view s = text;
  if (s.starts_with('+') || s.starts_with('-')) s.remove_prefix(1);
  if (const std::size_t at = s.find(mark); at != std::string_view::npos) {
    if (!digits(s.substr(at + 1))) return false;
    s = s.substr(0, at);
  }
  const std::size_t first = s.find(sep);
  if (first == std::string_view::npos || first == 0 || first > 3 || s.front() == '0' ||
      !digits(s.substr(0, first)))
    return false;
  groups = 0;
  for (std::size_t at = first; at < s.size(); at += 4, ++groups)
    if (s[at] != sep || !digits(s.substr(at + 1, 3)) || at + 4 > s.size()) return false;
  plain.clear();
  for (char c : text)
    if (c != sep) plain += c == mark ? '.' : c;
  return true;
}

// Whether `text` is a number with a decimal comma, no point and no comma groups ("12,5", "-0,950", not
// "1,200").
bool decimal_comma(std::string_view text) noexcept {
  if (text.starts_with('+') || text.starts_with('-')) text.remove_prefix(1);
  const std::size_t comma = text.find(',');
  const bool groups = comma >= 1 && comma <= 3 && text.front() != '0' && text.size() == comma + 4;
  return comma != std::string_view::npos && digits(text.substr(0, comma)) && digits(text.substr(comma + 1)) &&
         !groups;
}

}  // namespace

bool freematics_line(std::string_view line) noexcept {
  line = trim(line);
  const std::size_t colon = line.find(':'), equals = line.find('=');
  return colon != std::string_view::npos && equals != std::string_view::npos && colon < equals &&
         digits(line.substr(0, colon)) && digits(line.substr(colon + 1, equals - colon - 1), true);
}

Cell DigitGroups::read(std::string_view cell, std::string_view column) {
  const Cell as_read = parse_cell(cell, column);
  if (as_read.kind == CellKind::kMissing) return as_read;
  auto at = std::find_if(columns_.begin(), columns_.end(), [&](const Column& c) { return c.name == column; });
  if (at == columns_.end()) at = columns_.insert(columns_.end(), Column{std::string(column)});
  const std::string_view written = reader_.as_written(cell);
  const auto keep = [&](bool points) {
    grouped_.push_back(
        {reader_.number, static_cast<std::size_t>(at - columns_.begin()), std::string(written), points});
  };
  if (decimal_comma(written)) ++at->decimal_comma;  // "12,5": a bad cell where the point is the mark
  std::string plain;
  std::size_t groups = 0;
  if (!reader_.commas_are_marks()) {
    if (as_read.kind == CellKind::kNumber) {
      ++at->plain;
      return as_read;
    }
    if (!digit_groups(written, ',', '.', plain, groups)) return as_read;
    Cell number = parse_cell(plain, column);
    if (number.kind == CellKind::kNumber) keep(false);
    return number;
  }
  if (!digit_groups(written, '.', ',', plain, groups)) return as_read;
  if (groups == 1 && written.find(',') == std::string_view::npos) {  // "1.200": 1.2, unless the column says
    if (as_read.kind == CellKind::kNumber) keep(true);
    return as_read;
  }
  return parse_cell(plain, column);  // "1.234,5", "1.234.567"
}

std::optional<std::string> DigitGroups::problem(std::size_t line) const {
  auto g = std::lower_bound(grouped_.begin(), grouped_.end(), line,
                            [](const Grouped& a, std::size_t l) { return a.line < l; });
  for (; g != grouped_.end() && g->line == line; ++g) {
    const Column& c = columns_[g->column];
    if (g->points ? c.decimal_comma == 0 : c.plain > 0 && c.decimal_comma == 0) continue;
    return std::string("a thousands separator or a decimal ") + (g->points ? "point" : "comma") +
           "? in column " + c.name + ": " + quoted(g->text) +
           (c.decimal_comma > 0 ? " (other cells of the column have decimal commas)"
                                : " (no other cell of the column is a number without a comma)");
  }
  return std::nullopt;
}

bool same_name(std::string_view a, std::string_view b) noexcept {
  const auto space = [](char c) { return std::isspace(static_cast<unsigned char>(c)) != 0; };
  std::size_t i = 0, j = 0;
  while (true) {
    while (i < a.size() && space(a[i]))
      ++i;
    while (j < b.size() && space(b[j]))
      ++j;
    if (i == a.size() || j == b.size()) return i == a.size() && j == b.size();
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[j])))
      return false;
    ++i, ++j;
  }
}

std::optional<std::size_t> find_column(const std::vector<std::string>& header, std::string_view name) {
  for (std::size_t i = 0; i < header.size(); ++i)
    if (same_name(header[i], name)) return i;
  return std::nullopt;
}

namespace {

// Whether `word` is a 12-hour clock's "AM" or "PM" (any case); `pm` says which.
bool meridiem(std::string_view word, bool& pm) noexcept {
  if (word.size() != 2 || std::tolower(static_cast<unsigned char>(word[1])) != 'm') return false;
  const int c = std::tolower(static_cast<unsigned char>(word[0]));
  pm = c == 'p';
  return c == 'a' || c == 'p';
}

}  // namespace

std::optional<std::pair<double, double>> parse_clock(std::string_view text) {
  // The time is the last word holding a colon that starts with a digit ("GMT+08:00" in Torque's GPS Time
  // is a zone, not the time); "AM" or "PM" as the word right after it or the end of it makes it a 12-hour
  // clock (not elsewhere: "am 23.02.2022 14:42:46" is German for "on").
  std::string_view token;
  bool twelve_hour = false, pm = false;
  bool after_clock = false;  // the word before was the time
  std::size_t start = 0;
  while (start <= text.size()) {
    std::size_t end = text.find(' ', start);
    if (end == std::string_view::npos) end = text.size();
    std::string_view word = text.substr(start, end - start);
    start = end + 1;
    if (word.empty()) continue;
    if (bool p = false; meridiem(word, p)) {
      if (after_clock) {
        twelve_hour = true;
        pm = p;
      }
      after_clock = false;
      continue;
    }
    after_clock = false;
    if (word.find(':') == std::string_view::npos || !std::isdigit(static_cast<unsigned char>(word.front())))
      continue;
    after_clock = true;
    twelve_hour = meridiem(word.substr(word.size() - 2), pm);  // "1:05:00PM"
    if (twelve_hour) word.remove_suffix(2);
    // ISO 8601 ("2022-02-23T06:34:27.403Z", "...27.403+08:00"): the time after the T, without its zone.
    if (const std::size_t t = word.find_first_of("Tt"); t != std::string_view::npos)
      word.remove_prefix(t + 1);
    if (const std::size_t zone = word.find_first_of("Zz+-"); zone != std::string_view::npos)
      word = word.substr(0, zone);
    token = word;
  }
  double parts[3] = {0, 0, 0};
  int count = 0;
  std::size_t pos = 0;
  while (count < 3) {
    std::size_t colon = token.find(':', pos);
    const std::string_view part =
        token.substr(pos, colon == std::string_view::npos ? token.npos : colon - pos);
    const auto [ptr, ec] = std::from_chars(part.data(), part.data() + part.size(), parts[count]);
    if (part.empty() || ec != std::errc() || ptr != part.data() + part.size() ||
        !std::isfinite(parts[count]) || parts[count] < 0)
      return std::nullopt;
    ++count;
    if (colon == std::string_view::npos) break;
    pos = colon + 1;
    if (count == 3) return std::nullopt;
  }
  // A clock's fields stay below their wrap: minutes and seconds below 60, hours below 24 ("99:02.0" in a
  // run of "10:0x" is a corrupt cell, not a time an hour and a half on).
  if (parts[count - 1] >= 60.0 || (count >= 2 && parts[count - 2] >= 60.0) ||
      (count == 3 && parts[0] >= 24.0))
    return std::nullopt;
  if (twelve_hour) {  // hh:mm[:ss] AM/PM: 12 AM is midnight, 12 PM noon
    if (parts[0] < 1.0 || parts[0] > 12.0) return std::nullopt;
    parts[0] = std::fmod(parts[0], 12.0) + (pm ? 12.0 : 0.0);
    return std::make_pair(parts[0] * 3600.0 + parts[1] * 60.0 + parts[2], 86400.0);
  }
  if (count == 2) return std::make_pair(parts[0] * 60.0 + parts[1], 3600.0);
  if (count == 3) return std::make_pair(parts[0] * 3600.0 + parts[1] * 60.0 + parts[2], 86400.0);
  return std::nullopt;
}

std::vector<TimeDrop> time_order_drops(std::span<const double> t) {
  std::vector<TimeDrop> drops;
  const std::size_t n = t.size();
  std::optional<std::size_t> last;  // the last row kept
  char buf[96];
  for (std::size_t i = 0; i < n; ++i) {
    if (last && t[i] < t[*last]) {
      std::snprintf(buf, sizeof buf, "time goes backwards (%.6g after %.6g)", t[i], t[*last]);
      drops.push_back({i, buf});
      continue;
    }
    if (i + 1 < n && t[i] > t[i + 1]) {
      const bool next_follows =
          last ? t[*last] <= t[i + 1] : i + 2 < n && t[i + 1] <= t[i + 2] && t[i] > t[i + 2];
      if (next_follows) {
        std::snprintf(buf, sizeof buf, "time %.6g is ahead of the rows around it", t[i]);
        drops.push_back({i, buf});
        continue;
      }
    }
    last = i;
  }
  return drops;
}

std::string cells_problem(std::size_t have, std::size_t need) {
  return "too few cells (" + std::to_string(have) + ", need " + std::to_string(need) + ")";
}

void fold(std::string_view name, std::string& out) {
  out.clear();
  for (char c : name)
    if (!std::isspace(static_cast<unsigned char>(c)) && c != '_')
      out += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
}

std::string folded(std::string_view name) {
  std::string out;
  fold(name, out);
  return out;
}

bool holds(std::string_view text, std::initializer_list<std::string_view> parts) noexcept {
  return std::any_of(parts.begin(), parts.end(),
                     [&](std::string_view part) { return text.find(part) != std::string_view::npos; });
}

bool summary_column(std::string_view name) noexcept {
  return holds(name, {"average", "avg", "max", "min", "limit"});
}

}  // namespace gearpulse::log_reading
