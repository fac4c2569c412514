#include "core/sample_io.hpp"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <istream>
#include <limits>
#include <optional>
#include <ostream>

namespace gearpulse {
namespace {

constexpr double kKmhToMs = 1.0 / 3.6;
constexpr double kMphToMs = 0.44704;
constexpr double kSecondsPerMinute = 60.0;  // freq = rpm / 60

std::string_view trim(std::string_view s) noexcept {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front())))
    s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back())))
    s.remove_suffix(1);
  if (s.size() >= 2 && s.front() == '"' && s.back() == '"') s = trim(s.substr(1, s.size() - 2));
  return s;
}

// Splits on the file's delimiter (Carloop uses ", " and a trailing comma: trimming handles the first, the
// second only adds an empty cell past the last column). At most `limit` cells are kept, so that a row of
// millions of commas costs no more than the columns read from it; returns false when cells were left
// unsplit.
bool split_cells(std::string_view line, std::vector<std::string_view>& cells, std::size_t limit,
                 char delimiter) {
  cells.clear();
  std::size_t start = 0;
  while (cells.size() < limit) {
    const std::size_t comma = line.find(delimiter, start);
    if (comma == std::string_view::npos) {
      cells.push_back(trim(line.substr(start)));
      return true;
    }
    cells.push_back(trim(line.substr(start, comma - start)));
    start = comma + 1;
  }
  return false;
}

// A header wider than this is not a log (Torque's widest exports have a few hundred columns).
constexpr std::size_t kMaxColumns = 4096;

std::string quoted(std::string_view cell) {
  constexpr std::size_t kMaxShown = 24;
  std::string out = "'";
  for (char c : cell.substr(0, kMaxShown))
    out += std::isprint(static_cast<unsigned char>(c)) ? c : '?';
  if (cell.size() > kMaxShown) out += "...";
  return out + "'";
}

enum class CellKind { kMissing, kNumber, kBad };

struct Cell {
  CellKind kind = CellKind::kMissing;
  double value = kMissing;
  std::string problem;  // set when kind == kBad
};

// `spreadsheet_missing`: tokens that Torque and spreadsheets write for "no value" ("-", "#N/A", "#DIV/0!").
Cell parse_cell(std::string_view text, std::string_view column, bool spreadsheet_missing) {
  Cell cell;
  if (text.empty()) return cell;
  if (spreadsheet_missing && (text == "-" || text.front() == '#' || text == "N/A")) return cell;
  double value = 0.0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || ptr != text.data() + text.size()) {
    cell.kind = CellKind::kBad;
    cell.problem = "not a number in column " + std::string(column) + ": " + quoted(text);
    return cell;
  }
  if (!std::isfinite(value)) {
    cell.kind = CellKind::kBad;
    cell.problem = "non-finite value in column " + std::string(column) + ": " + quoted(text);
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

// Header names compare without case and without spaces: Torque writes "Engine RPM(rpm)" in one version and
// "Engine RPM (rpm)" in another, "GPS Speed(km/h)" beside "GPS Speed (Meters/second)".
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

// Clock time of day from Torque's time columns: "06:37.7" (mm:ss.s, as a spreadsheet re-saved it),
// "19:06:38" inside "Thu Jan 11 19:06:38 EST 2018", "06:34:27.403" inside "23-Feb-2022 06:34:27.403".
// Returns seconds and the period after which the clock wraps (an hour or a day).
std::optional<std::pair<double, double>> parse_clock(std::string_view text) {
  std::string_view token;
  std::size_t start = 0;
  while (start <= text.size()) {
    std::size_t end = text.find(' ', start);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view word = text.substr(start, end - start);
    if (word.find(':') != std::string_view::npos) token = word;
    start = end + 1;
  }
  if (token.empty()) return std::nullopt;
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
  if (count == 2) return std::make_pair(parts[0] * 60.0 + parts[1], 3600.0);
  if (count == 3) return std::make_pair(parts[0] * 3600.0 + parts[1] * 60.0 + parts[2], 86400.0);
  return std::nullopt;
}

// The rows of a log (their times, in file order) to drop so that its time never runs backwards, each
// with its reason, in row order. A row whose time jumps ahead of the rows on both sides (a corrupt cell)
// is the bad one, not every row after it: ahead of the next row, which follows on from the last row kept
// (or, for the rows before any is kept, from which the row after it follows on while the jump stays ahead
// of that one too). Otherwise a row behind the last row kept is the bad one (a clock that restarts keeps
// the rows before the restart).
struct TimeDrop {
  std::size_t row;
  std::string reason;
};
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

// Collects samples and skip reports; enforces the rules common to every format.
class LogBuilder {
 public:
  LogBuilder(std::string_view name, const ReadOptions& options) : options_(options) { log_.name = name; }
  [[nodiscard]] double row_seconds() const noexcept { return options_.row_seconds; }

  // Reports a bad row. The messages kept are those of the first rows in the file, in line order, whichever
  // order the reader finds them in (a row's time is judged once the rows after it are read).
  void skip(std::size_t line, std::string_view reason) {
    ++log_.skipped_count;
    const auto at = std::upper_bound(skipped_lines_.begin(), skipped_lines_.end(), line);
    if (static_cast<std::size_t>(at - skipped_lines_.begin()) >= options_.max_messages) return;
    log_.skipped.insert(log_.skipped.begin() + (at - skipped_lines_.begin()),
                        log_.name + ":" + std::to_string(line) + ": " + std::string(reason));
    skipped_lines_.insert(at, line);
    if (skipped_lines_.size() > options_.max_messages) {
      skipped_lines_.pop_back();
      log_.skipped.pop_back();
    }
  }
  // Returns false (and reports) when t runs backwards or a value is beyond any road vehicle.
  bool add(std::size_t line, Sample s) {
    // A road vehicle's speed, and an engine-related frequency (crank speed up to a redline of 30,000 rpm
    // and its harmonics, or a tracked ripple): anything beyond is a unit mix-up or a corrupt cell.
    constexpr double kMaxSpeed = 150.0;   // m/s (540 km/h)
    constexpr double kMaxFreq = 20000.0;  // Hz
    constexpr double kMinFreq = 1e-3;     // Hz: below it (but above 0, an engine at rest) nothing turns
    char buf[96];
    if (!std::isfinite(s.t)) {  // the readers bound their time cells; this holds for any caller
      skip(line, "time is not a finite number");
      return false;
    }
    if (s.has_speed() && s.speed > kMaxSpeed) {
      std::snprintf(buf, sizeof buf, "speed %.6g m/s is beyond any road vehicle", s.speed);
      skip(line, buf);
      return false;
    }
    if (s.has_freq() && (s.freq > kMaxFreq || (s.freq > 0.0 && s.freq < kMinFreq))) {
      std::snprintf(buf, sizeof buf, "frequency %.6g Hz is outside any engine's", s.freq);
      skip(line, buf);
      return false;
    }
    // The readers drop rows out of time order before (time_order_drops); this holds for any caller.
    if (!log_.samples.empty() && s.t < log_.samples.back().t) {
      std::snprintf(buf, sizeof buf, "time goes backwards (%.6g after %.6g)", s.t, log_.samples.back().t);
      skip(line, buf);
      return false;
    }
    log_.samples.push_back(s);
    add_repeat(s.t);
    return true;
  }
  // A row carried by the sample added last (its own, or one an OBD row repeats between refreshes), at
  // time t, kept in time order.
  void add_repeat(double t) {
    if (options_.keep_rows && !log_.samples.empty())
      log_.rows.push_back({log_.rows.empty() ? t : std::max(t, log_.rows.back().t), log_.samples.size() - 1});
  }
  SampleLog& log() noexcept { return log_; }
  [[nodiscard]] bool keeps_rows() const noexcept { return options_.keep_rows; }

  SampleLog finish() {
    const bool usable = std::any_of(log_.samples.begin(), log_.samples.end(),
                                    [](const Sample& s) { return s.has_speed() || s.has_freq(); });
    if (!usable) {
      std::string msg = log_.name + ": no usable samples";
      if (log_.skipped_count > 0) {
        msg += " (" + std::to_string(log_.skipped_count) +
               (log_.skipped_count == 1 ? " bad row" : " bad rows") + "; first: " + log_.skipped.front() +
               ")";
      } else if (log_.samples.empty() && log_.repeated_rows == 0) {
        msg += " (no data rows after the header)";
      } else {
        msg += " (every row lacks both speed and frequency)";
      }
      throw SampleFileError(msg);
    }
    return std::move(log_);
  }

 private:
  const ReadOptions& options_;
  SampleLog log_;
  std::vector<std::size_t> skipped_lines_;  // the line of each message in log_.skipped
};

// A reader's rows, in file order, walked against their time_order_drops(): keep() reports a dropped row
// as skipped and returns false.
class TimeOrder {
 public:
  template <class Rows, class Time>
  TimeOrder(const Rows& rows, Time time) {
    std::vector<double> t;
    t.reserve(rows.size());
    for (const auto& r : rows)
      t.push_back(time(r));
    drops_ = time_order_drops(t);
    next_ = drops_.begin();
  }
  bool keep(std::size_t row, std::size_t line, LogBuilder& out) {
    if (next_ == drops_.end() || next_->row != row) return true;
    out.skip(line, (next_++)->reason);
    return false;
  }

 private:
  std::vector<TimeDrop> drops_;
  std::vector<TimeDrop>::const_iterator next_;
};

bool blank(std::string_view line) {
  return trim(line).empty();
}

std::string cells_problem(std::size_t have, std::size_t need) {
  return "too few cells (" + std::to_string(have) + ", need " + std::to_string(need) + ")";
}

// A log's lines. The delimiter is a comma unless the header has none and has semicolons or tabs (a
// spreadsheet saved where the comma is the decimal mark): then a comma in a data line is a decimal mark.
struct LineReader {
  std::istream& in;
  std::string line;
  std::size_t number = 0;
  char delimiter = ',';
  bool next() {
    if (!std::getline(in, line)) return false;
    ++number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (number == 1 && line.size() >= 3 && line.compare(0, 3, "\xEF\xBB\xBF") == 0) line.erase(0, 3);
    if (delimiter != ',') std::replace(line.begin(), line.end(), ',', '.');
    return true;
  }
  void detect_delimiter() noexcept {
    if (line.find(',') != std::string::npos) return;
    if (line.find(';') != std::string::npos)
      delimiter = ';';
    else if (line.find('\t') != std::string::npos)
      delimiter = '\t';
  }
  bool cells(std::vector<std::string_view>& out, std::size_t limit) const {
    return split_cells(line, out, limit, delimiter);
  }
  // The next data line that is not blank, split into its first `need` cells; one with fewer is reported
  // and passed over. False at the end. `rows` counts the lines that are not blank, short ones included.
  bool next_row(std::vector<std::string_view>& out, std::size_t need, LogBuilder& log) {
    while (next()) {
      if (blank(line)) continue;
      ++rows;
      cells(out, need);
      if (out.size() >= need) return true;
      log.skip(number, cells_problem(out.size(), need));
    }
    return false;
  }
  std::size_t rows = 0;
};

void read_generic(LineReader& reader, const std::vector<std::string>& header, LogBuilder& out) {
  const std::size_t it = *find_column(header, "t");
  const std::size_t is = *find_column(header, "speed");
  const std::size_t iff = *find_column(header, "freq");
  const std::size_t need = std::max({it, is, iff}) + 1;
  out.log().format = SampleFileFormat::kGeneric;
  out.log().speed_column = "speed";
  std::vector<std::string_view> cells;
  std::vector<std::size_t> lines;
  std::vector<Sample> rows;
  while (reader.next_row(cells, need, out)) {
    const Cell t = parse_cell(cells[it], "t", false);
    const Cell v = parse_cell(cells[is], "speed", false);
    const Cell f = parse_cell(cells[iff], "freq", false);
    if (t.kind == CellKind::kMissing) {
      out.skip(reader.number, "missing t");
      continue;
    }
    const Cell* bad = t.kind == CellKind::kBad ? &t : v.kind == CellKind::kBad ? &v : &f;
    if (bad->kind == CellKind::kBad) {
      out.skip(reader.number, bad->problem);
      continue;
    }
    lines.push_back(reader.number);
    rows.push_back(Sample{t.value, v.value, f.value});
  }
  TimeOrder order(rows, [](const Sample& r) { return r.t; });
  for (std::size_t i = 0; i < rows.size(); ++i)
    if (order.keep(i, lines[i], out)) out.add(lines[i], rows[i]);
}

// The Carloop logger writes rows at a steady rate (it polls its PIDs round-robin) but its run-time
// counter has a resolution of one second and is itself refreshed only once per cycle (~1.8 s). The time of
// a row is therefore estimated from its row number by a local straight-line fit through the points where
// the counter changed (middle of its one-second step), which brings the timing error well below a second.
std::vector<double> smooth_row_times(const std::vector<double>& rows, const std::vector<double>& refresh_row,
                                     const std::vector<double>& refresh_t) {
  constexpr std::size_t kHalfWindow = 8;  // refresh points each side (~15 s)
  std::vector<double> out(rows.size());
  double previous = -std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const auto k = static_cast<std::size_t>(
        std::lower_bound(refresh_row.begin(), refresh_row.end(), rows[i]) - refresh_row.begin());
    const std::size_t lo = k > kHalfWindow ? k - kHalfWindow : 0;
    const std::size_t hi = std::min(refresh_row.size(), k + kHalfWindow + 1);
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    const double n = static_cast<double>(hi - lo);
    for (std::size_t m = lo; m < hi; ++m) {
      const double x = refresh_row[m] - rows[i];
      sx += x;
      sy += refresh_t[m];
      sxx += x * x;
      sxy += x * refresh_t[m];
    }
    const double det = n * sxx - sx * sx;
    double t = n > 0 ? sy / n : rows[i];
    if (n >= 2 && det > 1e-9) t = (sy * sxx - sx * sxy) / det;  // intercept at rows[i]
    out[i] = std::max(t, previous);
    previous = out[i];
  }
  return out;
}

// Where an OBD log's values are: its columns, the speed's unit and the time's.
struct ObdLayout {
  SampleFileFormat format = SampleFileFormat::kSpeedRpm;
  std::size_t rpm = 0, speed = 0;
  std::optional<std::size_t> time;  // none: the row counter times ReadOptions::row_seconds
  double speed_to_ms = kKmhToMs;
  double time_to_s = 1.0;
  std::string speed_column;
};

// A column name folded for matching: lower case, no spaces or underscores.
std::string folded(std::string_view name) {
  std::string out;
  for (char c : name)
    if (!std::isspace(static_cast<unsigned char>(c)) && c != '_')
      out += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

bool holds(std::string_view text, std::initializer_list<std::string_view> parts) noexcept {
  return std::any_of(parts.begin(), parts.end(),
                     [&](std::string_view part) { return text.find(part) != std::string_view::npos; });
}

// The speed unit a column's name states (m/s per unit), or 0.
double speed_unit(std::string_view name) noexcept {
  if (holds(name, {"km/h", "kmh", "kph", "km/hr"})) return kKmhToMs;
  if (holds(name, {"mph", "mi/h"})) return kMphToMs;
  if (holds(name, {"m/s", "mps", "meters/second", "metres/second"})) return 1.0;
  return 0.0;
}

// Logs of other OBD apps and data sets, found by their column names (see folded()): the first column
// whose name holds "rpm"; a speed column, whose name holds "speed" and states its unit, a GPS one (its name
// holds "gps") or another as `--speed` asks (auto: GPS when there is one); a time column named time,
// timestamp, seconds or t, in milliseconds when its name ends in ms, (ms) or [ms]. None when the header
// has no rpm or no speed column; an error naming the column when the only speed has no unit.
std::optional<ObdLayout> named_layout(const std::vector<std::string>& header, TorqueSpeed choice,
                                      const std::string& name) {
  ObdLayout layout;
  layout.format = SampleFileFormat::kColumns;
  std::optional<std::size_t> rpm, gps, other, unitless;
  for (std::size_t i = 0; i < header.size(); ++i) {
    const std::string f = folded(header[i]);
    if (f.find("rpm") != std::string::npos) {
      if (!rpm) rpm = i;
      continue;
    }
    std::string base = f.substr(0, f.find_first_of("(["));
    bool ms = f.substr(base.size()) == "(ms)" || f.substr(base.size()) == "[ms]";
    if (!ms && base.size() > 2 && base.ends_with("ms")) {
      base.resize(base.size() - 2);
      ms = true;
    }
    if (!layout.time && (base == "time" || base == "timestamp" || base == "seconds" || base == "t")) {
      layout.time = i;
      layout.time_to_s = ms ? 1e-3 : 1.0;
      continue;
    }
    if (f.find("speed") == std::string::npos) continue;
    if (speed_unit(f) == 0.0) {
      if (!unitless) unitless = i;
    } else if (f.find("gps") != std::string::npos) {
      if (!gps) gps = i;
    } else if (!other) {
      other = i;
    }
  }
  if (!rpm) return std::nullopt;
  std::optional<std::size_t> speed = choice == TorqueSpeed::kObd ? other : gps ? gps : other;
  if (choice == TorqueSpeed::kGps) speed = gps;
  if (!speed) {
    if (choice != TorqueSpeed::kAuto && (gps || other))
      throw SampleFileError(name + ":1: no " + (choice == TorqueSpeed::kGps ? "GPS" : "OBD") +
                            " speed column (a name holding 'speed' and a unit" +
                            (choice == TorqueSpeed::kGps ? ", and 'GPS')" : ", without 'GPS')"));
    if (unitless)
      throw SampleFileError(name + ":1: speed column " + quoted(header[*unitless]) +
                            " states no unit: name it with km/h, mph or m/s");
    return std::nullopt;
  }
  layout.rpm = *rpm;
  layout.speed = *speed;
  layout.speed_to_ms = speed_unit(folded(header[*speed]));
  layout.speed_column = header[*speed];
  return layout;
}

// One OBD row as read: its line, its place among the data rows, its time, rpm and speed (the log's unit).
struct ObdRow {
  std::size_t line;
  double counter, t, rpm, speed;
};

// OBD values held between refreshes, in file order. A row whose rpm and speed both equal the previous
// row's carries nothing new (a logger polls many PIDs round-robin), so it is dropped. Times count from the
// first row but in Carloop logs (the engine's run time).
void add_obd_rows(std::vector<ObdRow>& parsed, LogBuilder& out, const ObdLayout& layout) {
  const SampleFileFormat format = layout.format;
  const bool timed = layout.time.has_value();
  double last_rpm = kMissing, last_speed = kMissing, last_t = -std::numeric_limits<double>::infinity();
  bool have_last = false;
  std::vector<std::size_t> lines;
  std::vector<double> rows, refresh_row, refresh_t;
  std::vector<Sample> kept;
  // Rows repeating held values (kept for SampleLog::rows only): row counter, own time, the kept row.
  struct Repeat {
    double row, t;
    std::size_t of, line;
  };
  std::vector<Repeat> repeats;
  if (format != SampleFileFormat::kCarloop && timed && !parsed.empty()) {
    const double t0 = parsed.front().t;
    for (ObdRow& p : parsed)
      p.t -= t0;
  }
  TimeOrder order(parsed, [](const ObdRow& p) { return p.t; });
  for (std::size_t i = 0; i < parsed.size(); ++i) {
    const ObdRow& p = parsed[i];
    if (!order.keep(i, p.line, out)) continue;
    if (p.t != last_t) {
      refresh_row.push_back(p.counter);
      refresh_t.push_back(p.t + 0.5);
    }
    last_t = p.t;
    const auto same = [](double a, double b) { return (std::isnan(a) && std::isnan(b)) || a == b; };
    if (have_last && same(p.rpm, last_rpm) && same(p.speed, last_speed)) {
      ++out.log().repeated_rows;
      if (out.keeps_rows()) repeats.push_back({p.counter, p.t, kept.size() - 1, p.line});
      continue;
    }
    last_rpm = p.rpm;
    last_speed = p.speed;
    have_last = true;
    lines.push_back(p.line);
    rows.push_back(p.counter);
    kept.push_back(Sample{p.t, p.speed * layout.speed_to_ms, p.rpm / kSecondsPerMinute});
  }
  if (format == SampleFileFormat::kCarloop && timed && refresh_row.size() >= 2) {
    // The counter on a row is the whole second at its last refresh, at most one polling round old: the
    // estimate stays within that (it matters only at the ends of a log, where the fit is one-sided).
    constexpr double kMaxCounterAge = 3.0;  // s: one second of resolution plus a polling round
    const auto estimate = [&](const std::vector<double>& at, auto&& own_t, auto&& set_t) {
      const std::vector<double> times = smooth_row_times(at, refresh_row, refresh_t);
      double previous = -std::numeric_limits<double>::infinity();
      for (std::size_t i = 0; i < at.size(); ++i) {
        previous = std::max(previous, std::clamp(times[i], own_t(i), own_t(i) + kMaxCounterAge));
        set_t(i, previous);
      }
    };
    estimate(
        rows, [&](std::size_t i) { return kept[i].t; }, [&](std::size_t i, double t) { kept[i].t = t; });
    if (!repeats.empty()) {
      std::vector<double> repeat_rows(repeats.size());
      for (std::size_t i = 0; i < repeats.size(); ++i)
        repeat_rows[i] = repeats[i].row;
      estimate(
          repeat_rows, [&](std::size_t i) { return repeats[i].t; },
          [&](std::size_t i, double t) { repeats[i].t = t; });
    }
  }
  std::size_t r = 0;
  for (std::size_t i = 0; i < kept.size(); ++i) {
    const bool added = out.add(lines[i], kept[i]);
    for (; r < repeats.size() && repeats[r].of == i; ++r) {
      if (added)
        out.add_repeat(repeats[r].t);
      else
        out.skip(repeats[r].line, "repeats the values of the bad row at line " + std::to_string(lines[i]));
    }
  }
}

// Carloop, `speed,rpm` and named-column logs. A named-column log's times count from its first row; its
// time cells may be clocks.
void read_obd(LineReader& reader, LogBuilder& out, const ObdLayout& layout) {
  const SampleFileFormat format = layout.format;
  const std::optional<std::size_t> it = layout.time;
  const std::size_t irpm = layout.rpm, ispeed = layout.speed;
  out.log().speed_column = layout.speed_column;
  out.log().format = format;
  out.log().time_from_rows = !it.has_value();
  const std::size_t need = std::max({it.value_or(0), irpm, ispeed}) + 1;
  std::vector<std::string_view> cells;
  std::vector<ObdRow> parsed;
  double last_clock = -1.0, clock_offset = 0.0;  // a clock's time of day, unwrapped past midnight
  while (reader.next_row(cells, need, out)) {
    const auto counter = static_cast<double>(reader.rows - 1);
    const Cell rpm = parse_cell(cells[irpm], "rpm", false);
    const Cell speed = parse_cell(cells[ispeed], "speed", false);
    Cell t;
    t.kind = CellKind::kNumber;
    t.value = counter * out.row_seconds();
    if (it) {
      t = parse_cell(cells[*it], "time", false);
      // No log's clock in seconds reaches 1e11 (the year 5138 since 1970): beyond, milliseconds.
      constexpr double kMillisecondsAtLeast = 1e11;
      if (t.kind == CellKind::kNumber)
        t.value *=
            format == SampleFileFormat::kColumns && t.value >= kMillisecondsAtLeast ? 1e-3 : layout.time_to_s;
      const auto clock = format == SampleFileFormat::kColumns && t.kind == CellKind::kBad
                             ? parse_clock(cells[*it])
                             : std::nullopt;
      if (clock) {
        if (last_clock >= 0.0 && clock->first < last_clock - clock->second / 2) clock_offset += clock->second;
        last_clock = clock->first;
        t = Cell{CellKind::kNumber, clock->first + clock_offset, {}};
      }
    }
    if (t.kind == CellKind::kMissing) {
      out.skip(reader.number, "missing time");
      continue;
    }
    const Cell* bad = t.kind == CellKind::kBad ? &t : rpm.kind == CellKind::kBad ? &rpm : &speed;
    if (bad->kind == CellKind::kBad) {
      out.skip(reader.number, bad->problem);
      continue;
    }
    parsed.push_back({reader.number, counter, t.value, rpm.value, speed.value});
  }
  add_obd_rows(parsed, out, layout);
}

// One reading per row (`SECONDS;PID;VALUE;UNITS`, as phone OBD apps such as Car Scanner export): the
// engine's rpm (the PID named Engine RPM, else the first whose unit or name is rpm) and a speed (a PID
// whose name holds "speed" but no average or maximum, with a speed unit; GPS or OBD as `--speed` asks,
// auto: GPS when there is one) are read; each rpm reading is a row, with the speed at its time (below). A
// SECONDS clock that falls back by half a day has passed midnight.
void read_pid_rows(LineReader& reader, const std::vector<std::string>& header, LogBuilder& out,
                   TorqueSpeed choice) {
  const std::size_t it = *find_column(header, "SECONDS"), ipid = *find_column(header, "PID"),
                    ivalue = *find_column(header, "VALUE");
  const std::optional<std::size_t> iunit = find_column(header, "UNITS");
  const std::size_t need = std::max({it, ipid, ivalue, iunit.value_or(0)}) + 1;
  struct Reading {
    std::size_t line;
    double t, value;
    std::size_t pid;      // index into names
    double to_ms;         // speed unit of the row (0: none)
    std::string problem;  // why the value does not read (said only for the PIDs used)
  };
  std::vector<std::string> names;
  std::vector<std::string> units;  // of each PID's first reading, folded
  std::vector<Reading> readings;
  std::vector<std::string_view> cells;
  constexpr double kDay = 86400.0;
  double last_t = -1.0, offset = 0.0;
  while (reader.next_row(cells, need, out)) {
    const Cell t = parse_cell(cells[it], "time", false);
    const Cell value = parse_cell(cells[ivalue], "value", false);
    if (t.kind != CellKind::kNumber) {
      out.skip(reader.number, t.kind == CellKind::kMissing ? "missing time" : t.problem);
      continue;
    }
    if (value.kind == CellKind::kMissing) continue;  // a PID the car did not answer
    const std::string name = folded(cells[ipid]);
    auto known = std::find(names.begin(), names.end(), name);
    const std::size_t pid = static_cast<std::size_t>(known - names.begin());
    const std::string unit = iunit ? folded(cells[*iunit]) : std::string{};
    if (known == names.end()) {
      names.push_back(name);
      units.push_back(unit);
    }
    double seconds = t.value >= 1e11 ? t.value * 1e-3 : t.value;  // milliseconds since 1970, as above
    if (last_t >= 0.0 && seconds + offset < last_t - kDay / 2) offset += kDay;
    seconds += offset;
    last_t = seconds;
    readings.push_back(
        {reader.number, seconds, value.value, pid, speed_unit(unit.empty() ? name : unit), value.problem});
  }
  const auto find_pid = [&](auto&& good) -> std::optional<std::size_t> {
    for (std::size_t i = 0; i < names.size(); ++i)
      if (good(i)) return i;
    return std::nullopt;
  };
  std::optional<std::size_t> rpm = find_pid([&](std::size_t i) { return names[i] == "enginerpm"; });
  if (!rpm) rpm = find_pid([&](std::size_t i) { return units[i] == "rpm" || holds(names[i], {"rpm"}); });
  const auto speed_pid = [&](std::size_t i, bool gps) {
    return holds(names[i], {"speed"}) && !holds(names[i], {"average", "avg", "max", "min", "limit"}) &&
           speed_unit(units[i].empty() ? names[i] : units[i]) > 0.0 && holds(names[i], {"gps"}) == gps;
  };
  const std::optional<std::size_t> gps = find_pid([&](std::size_t i) { return speed_pid(i, true); });
  const std::optional<std::size_t> obd = find_pid([&](std::size_t i) { return speed_pid(i, false); });
  const std::optional<std::size_t> speed = choice == TorqueSpeed::kGps   ? gps
                                           : choice == TorqueSpeed::kObd ? obd
                                           : gps                         ? gps
                                                                         : obd;
  if (!rpm) throw SampleFileError(out.log().name + ": no engine rpm among the PIDs (a PID named or in rpm)");
  if (!speed)
    throw SampleFileError(out.log().name + ": no " +
                          (choice == TorqueSpeed::kGps   ? "GPS speed"
                           : choice == TorqueSpeed::kObd ? "OBD speed"
                                                         : "speed") +
                          " among the PIDs (a PID whose name holds 'speed', in km/h, mph or m/s)");
  ObdLayout layout;
  layout.format = SampleFileFormat::kPidRows;
  layout.time = it;
  layout.speed_to_ms = 1.0;  // each reading converted by its own unit
  layout.speed_column = names[*speed];
  out.log().format = layout.format;
  out.log().speed_column = layout.speed_column;
  // The speed at each rpm reading, interpolated between the speed readings on either side when they are
  // at most kMaxSpeedGap apart (a phone app polls each PID every few seconds; across a longer gap the
  // speed is not known): rpm and speed are read at different instants, and a speed held from its last
  // reading would pair every rpm with a speed up to a polling round old.
  constexpr double kMaxSpeedGap = 10.0;  // s
  struct SpeedAt {
    double t, v;
  };
  std::vector<SpeedAt> speeds;
  std::vector<const Reading*> revs;
  for (const Reading& r : readings) {
    if (r.pid != *rpm && r.pid != *speed) continue;
    if (!r.problem.empty()) {
      out.skip(r.line, r.problem);
      continue;
    }
    if (r.pid == *rpm)
      revs.push_back(&r);
    else
      speeds.push_back({r.t, r.value * r.to_ms});
  }
  std::stable_sort(speeds.begin(), speeds.end(),
                   [](const SpeedAt& a, const SpeedAt& b) { return a.t < b.t; });
  std::vector<ObdRow> rows;
  for (const Reading* r : revs) {
    const auto after = std::lower_bound(speeds.begin(), speeds.end(), r->t,
                                        [](const SpeedAt& a, double t) { return a.t < t; });
    double v = kMissing;
    if (after != speeds.end() && after->t == r->t) {
      v = after->v;
    } else if (after != speeds.end() && after != speeds.begin() &&
               after->t - (after - 1)->t <= kMaxSpeedGap) {
      const SpeedAt& before = *(after - 1);
      v = before.v + (after->v - before.v) * (r->t - before.t) / (after->t - before.t);
    }
    rows.push_back({r->line, static_cast<double>(rows.size()), r->t, r->value, v});
  }
  add_obd_rows(rows, out, layout);
}

struct SpeedColumn {
  const char* header;
  double to_ms;
  bool gps;
};
constexpr SpeedColumn kTorqueSpeeds[] = {
    {"GPS Speed (Meters/second)", 1.0, true}, {"Speed (GPS)(km/h)", kKmhToMs, true},
    {"GPS Speed (km/h)", kKmhToMs, true},     {"Speed (GPS)(mph)", kMphToMs, true},
    {"Speed (OBD)(km/h)", kKmhToMs, false},   {"Speed (OBD)(mph)", kMphToMs, false}};

// Torque's clock wraps every hour (mm:ss) or day (hh:mm:ss): the rows' times are unwrapped in file order.
// A clock cell that jumps away from the row before it while the row after it goes on from that one is
// corrupt: its row is skipped, and its jump is not taken for a wrap (one such cell, "45:00" among "10:0x",
// put every later row an hour on).
template <typename Row>
void unwrap_clock(std::vector<Row>& rows, LogBuilder& out) {
  constexpr double kJump = 60.0;  // s: a log's rows are a second or so apart; more is a pause or corrupt
  const auto apart = [](double a, double b, double period) {
    const double d = std::abs(a - b);
    return std::min(d, period - d);  // either way round the clock
  };
  double offset = 0.0, last = -1.0;
  std::size_t kept = 0;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    Row& r = rows[i];
    const double jump = last >= 0.0 ? apart(r.clock, last, r.period) : 0.0;
    if (jump > kJump && i + 1 < rows.size() && apart(rows[i + 1].clock, last, r.period) <= kJump) {
      char buf[96];
      std::snprintf(buf, sizeof buf, "time jumps %.0f s away from the rows around it",
                    std::abs(r.clock - last));
      out.skip(r.line, buf);
      continue;
    }
    if (last >= 0.0 && r.clock < last - r.period / 2) offset += r.period;
    last = r.clock;
    r.t = r.clock + offset;
    rows[kept++] = r;
  }
  rows.resize(kept);
}

void read_torque(LineReader& reader, const std::vector<std::string>& header, LogBuilder& out,
                 TorqueSpeed choice) {
  out.log().format = SampleFileFormat::kTorque;
  const std::size_t irpm = *find_column(header, "Engine RPM(rpm)");
  std::optional<std::size_t> itime = find_column(header, "Device Time");
  if (!itime) itime = find_column(header, "GPS Time");
  // First GPS and first OBD speed column present.
  std::optional<std::size_t> igps, iobd;
  const SpeedColumn* gps_col = nullptr;
  const SpeedColumn* obd_col = nullptr;
  for (const SpeedColumn& c : kTorqueSpeeds) {
    if (auto i = find_column(header, c.header)) {
      if (c.gps && !igps) igps = i, gps_col = &c;
      if (!c.gps && !iobd) iobd = i, obd_col = &c;
    }
  }
  if (choice == TorqueSpeed::kGps && !igps)
    throw SampleFileError(out.log().name + ":1: no GPS speed column ('GPS Speed (Meters/second)')");
  if (choice == TorqueSpeed::kObd && !iobd)
    throw SampleFileError(out.log().name + ":1: no OBD speed column ('Speed (OBD)(km/h)' or '(mph)')");

  struct Row {
    std::size_t line;
    double t, gps, obd, freq;
    double clock = -1.0, period = 0.0;  // time of day (s) and its wrap, when the log has a time column
  };
  std::vector<Row> rows;
  std::size_t need = irpm + 1;
  for (auto i : {itime, igps, iobd})
    if (i) need = std::max(need, *i + 1);
  std::vector<std::string_view> cells;
  std::size_t gps_count = 0;
  while (reader.next_row(cells, need, out)) {
    const auto row_time = static_cast<double>(reader.rows - 1);
    Row row{reader.number, row_time, kMissing, kMissing, kMissing};
    if (itime) {
      const auto clock = parse_clock(cells[*itime]);
      if (!clock) {
        out.skip(reader.number, "unreadable time " + quoted(cells[*itime]));
        continue;
      }
      row.clock = clock->first;
      row.period = clock->second;
    }
    const Cell rpm = parse_cell(cells[irpm], header[irpm], true);
    Cell gps, obd;
    if (igps) gps = parse_cell(cells[*igps], header[*igps], true);
    if (iobd) obd = parse_cell(cells[*iobd], header[*iobd], true);
    const Cell* bad = rpm.kind == CellKind::kBad ? &rpm : gps.kind == CellKind::kBad ? &gps : &obd;
    if (bad->kind == CellKind::kBad) {
      out.skip(reader.number, bad->problem);
      continue;
    }
    row.freq = rpm.value / kSecondsPerMinute;
    if (igps) row.gps = gps.value * gps_col->to_ms;
    if (iobd) row.obd = obd.value * obd_col->to_ms;
    if (std::isfinite(row.gps)) ++gps_count;
    rows.push_back(row);
  }
  if (itime) unwrap_clock(rows, out);
  const bool use_gps = choice == TorqueSpeed::kGps || (choice == TorqueSpeed::kAuto && gps_count > 0);
  if (!use_gps && !iobd)
    throw SampleFileError(out.log().name +
                          ":1: no speed values (no OBD speed column and no GPS speed value)");
  out.log().speed_column = use_gps ? gps_col->header : obd_col->header;
  // Times count from the first row kept (a first row dropped for a corrupt time would shift them all).
  TimeOrder order(rows, [](const Row& r) { return r.t; });
  std::optional<double> t0;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    if (!order.keep(i, r.line, out)) continue;
    if (!t0) t0 = r.t;
    out.add(r.line, Sample{r.t - *t0, use_gps ? r.gps : r.obd, r.freq});
  }
}

}  // namespace

std::string_view format_name(SampleFileFormat format) noexcept {
  switch (format) {
    case SampleFileFormat::kGeneric:
      return "csv";
    case SampleFileFormat::kTorque:
      return "torque";
    case SampleFileFormat::kCarloop:
      return "carloop";
    case SampleFileFormat::kSpeedRpm:
      return "speed-rpm";
    case SampleFileFormat::kColumns:
      return "columns";
    case SampleFileFormat::kPidRows:
      return "pid-rows";
  }
  return "unknown";
}

namespace {

// The generic format's units are the user's to get right; the two slips that still read are said. Speeds
// beyond any car's top speed (270 km/h as m/s) are most likely km/h; rows minutes apart, milliseconds.
void warn_units(SampleLog& log) {
  constexpr double kTopSpeed = 75.0;  // m/s
  constexpr double kSlowRows = 30.0;  // s between rows, at the median
  double top = 0.0;
  std::vector<double> steps;
  steps.reserve(log.samples.size());
  for (std::size_t i = 0; i < log.samples.size(); ++i) {
    if (std::isfinite(log.samples[i].speed)) top = std::max(top, log.samples[i].speed);
    if (i > 0 && log.samples[i].t > log.samples[i - 1].t)
      steps.push_back(log.samples[i].t - log.samples[i - 1].t);
  }
  char buf[256];
  if (top > kTopSpeed) {
    std::snprintf(
        buf, sizeof buf,
        ": speeds up to %.4g m/s (%.4g km/h): the t,speed,freq format takes m/s; is the speed column "
        "in km/h?",
        top, top * 3.6);
    log.warnings.push_back(log.name + buf);
  }
  if (steps.size() >= 10) {
    const auto mid = steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2);
    std::nth_element(steps.begin(), mid, steps.end());
    if (*mid > kSlowRows) {
      std::snprintf(buf, sizeof buf,
                    ": rows %.4g s apart at the median: the t,speed,freq format takes seconds; is t in ms?",
                    *mid);
      log.warnings.push_back(log.name + buf);
    }
  }
}

}  // namespace

SampleLog read_samples(std::istream& in, std::string_view name, const ReadOptions& options) {
  if (!(std::isfinite(options.row_seconds) && options.row_seconds > 0.0))
    throw std::invalid_argument("ReadOptions::row_seconds must be finite and above 0");
  LineReader reader{in, {}, 0};
  LogBuilder out(name, options);
  bool got_header = false;
  while (reader.next()) {
    if (!blank(reader.line)) {
      got_header = true;
      break;
    }
  }
  if (!got_header) {
    if (in.bad()) throw SampleFileError(std::string(name) + ": read error");
    throw SampleFileError(std::string(name) + ": empty file");
  }
  std::vector<std::string_view> views;
  reader.detect_delimiter();
  if (!reader.cells(views, kMaxColumns))
    throw SampleFileError(std::string(name) + ":" + std::to_string(reader.number) +
                          ": header has more than " + std::to_string(kMaxColumns) + " columns");
  std::vector<std::string> header(views.begin(), views.end());
  const auto has = [&](std::string_view column) { return find_column(header, column).has_value(); };

  // The generic header first: its further columns are ignored, whatever their names.
  if (has("t") && has("speed") && has("freq")) {
    read_generic(reader, header, out);
  } else if (has("Engine RPM(rpm)")) {
    read_torque(reader, header, out, options.torque_speed);
  } else if (has("ENGINE_RPM ()") && has("VEHICLE_SPEED ()")) {
    ObdLayout carloop{SampleFileFormat::kCarloop,
                      *find_column(header, "ENGINE_RPM ()"),
                      *find_column(header, "VEHICLE_SPEED ()"),
                      find_column(header, "ENGINE_RUN_TINE ()"),
                      kKmhToMs,
                      1.0,
                      "VEHICLE_SPEED ()"};  // sic: the logger's own spelling, RUN_TINE
    if (!carloop.time) carloop.time = find_column(header, "ENGINE_RUN_TIME ()");
    read_obd(reader, out, carloop);
  } else if (header.size() >= 2 && has("speed") && has("rpm")) {
    read_obd(reader, out,
             ObdLayout{SampleFileFormat::kSpeedRpm, *find_column(header, "rpm"),
                       *find_column(header, "speed"), std::nullopt, kKmhToMs, 1.0, "speed"});
  } else if (has("SECONDS") && has("PID") && has("VALUE")) {
    read_pid_rows(reader, header, out, options.torque_speed);
  } else if (auto layout = named_layout(header, options.torque_speed, std::string(name))) {
    read_obd(reader, out, *layout);
  } else {
    throw SampleFileError(std::string(name) + ":" + std::to_string(reader.number) + ": unrecognised header " +
                          quoted(reader.line) +
                          " (expected t,speed,freq, a Torque Pro, Carloop or speed,rpm log, or columns "
                          "named rpm and speed with a unit)");
  }
  if (in.bad()) throw SampleFileError(std::string(name) + ": read error");
  SampleLog log = out.finish();
  if (log.format == SampleFileFormat::kGeneric) warn_units(log);
  return log;
}

std::optional<SampleLog> read_wheel_speed(std::istream& in, const SampleLog& log) {
  const bool from_gps =
      std::any_of(std::begin(kTorqueSpeeds), std::end(kTorqueSpeeds),
                  [&](const SpeedColumn& c) { return c.gps && log.speed_column == c.header; });
  if (log.format != SampleFileFormat::kTorque || !from_gps) return std::nullopt;
  ReadOptions options;
  options.torque_speed = TorqueSpeed::kObd;
  try {
    return read_samples(in, log.name, options);
  } catch (const SampleFileError&) {
    return std::nullopt;  // no OBD speed column, or none usable
  }
}

void write_samples(std::ostream& out, std::span<const Sample> samples) {
  out << "t,speed,freq\n";
  char buf[96];
  for (const Sample& s : samples) {
    int n = std::snprintf(buf, sizeof buf, "%.17g,", s.t);
    if (s.has_speed())
      n += std::snprintf(buf + n, sizeof buf - static_cast<std::size_t>(n), "%.17g", s.speed);
    buf[n++] = ',';
    if (s.has_freq()) n += std::snprintf(buf + n, sizeof buf - static_cast<std::size_t>(n), "%.17g", s.freq);
    buf[n++] = '\n';
    out.write(buf, n);
  }
}

}  // namespace gearpulse
