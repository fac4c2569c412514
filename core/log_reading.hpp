#pragma once

// What every log reader is made of (cells, column names, clocks, time order, the builder that collects a
// log's samples and bad rows; the line reader is core/line_reader.hpp; the speeds' units core/log_units.cpp)
// and the readers of the OBD and Torque layouts, which core/sample_io.cpp picks by a log's header. Internal
// to core: the contract is core/sample_io.hpp.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <initializer_list>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/line_reader.hpp"
#include "core/sample_io.hpp"

namespace gearpulse::log_reading {

inline constexpr double kKmhToMs = 1.0 / 3.6;
inline constexpr double kMphToMs = 0.44704;
inline constexpr double kKnotToMs = 1852.0 / 3600.0;  // a nautical mile (1852 m) an hour
inline constexpr double kSecondsPerMinute = 60.0;     // freq = rpm / 60
// The units a user names (ReadOptions::speed_unit), and those a column states (stated_speed_to_ms()).
inline constexpr SpeedUnit kKmh{kKmhToMs, "km/h"}, kMph{kMphToMs, "mph"}, kMetresPerSecond{1.0, "m/s"},
    kKnots{kKnotToMs, "knots"};
inline constexpr SpeedUnit kSpeedUnits[] = {kKmh, kMph, kMetresPerSecond, kKnots};

std::string_view trim(std::string_view s) noexcept;

// Splits on the file's delimiter (Carloop uses ", " and a trailing comma: trimming handles the first, the
// second only adds an empty cell past the last column); a quoted cell keeps the delimiters inside it. At most
// `limit` cells are kept, so that a row of millions of commas costs no more than the columns read from it;
// returns false when cells were left unsplit.
bool split_cells(std::string_view line, std::vector<std::string_view>& cells, std::size_t limit,
                 char delimiter);

// A header wider than this is not a log (Torque's widest exports have a few hundred columns).
inline constexpr std::size_t kMaxColumns = 4096;

std::string quoted(std::string_view cell);

enum class CellKind { kMissing, kNumber, kBad };

struct Cell {
  CellKind kind = CellKind::kMissing;
  double value = kMissing;
  std::string problem;  // set when kind == kBad
};

// A cell that is empty or spells "no value" is missing: "-" (Torque), "NA", "N/A", "null" or "None"
// (python-OBD; any case), a spreadsheet's error ("#N/A", "#DIV/0!"). NaN is not: a number no computation
// should give, a bad cell.
Cell parse_cell(std::string_view text, std::string_view column);

// Header names compare without case and without spaces: Torque writes "Engine RPM(rpm)" in one version and
// "Engine RPM (rpm)" in another, "GPS Speed(km/h)" beside "GPS Speed (Meters/second)".
bool same_name(std::string_view a, std::string_view b) noexcept;

std::optional<std::size_t> find_column(const std::vector<std::string>& header, std::string_view name);

// Clock time of day from Torque's time columns: "06:37.7" (mm:ss.s, as a spreadsheet re-saved it),
// "19:06:38" inside "Thu Jan 11 19:06:38 EST 2018" or "Wed Feb 23 06:42:46 GMT+08:00 2022", "06:34:27.403"
// inside "23-Feb-2022 06:34:27.403" or ISO 8601 "2022-02-23T06:34:27.403Z" (its zone dropped), "1:05:09 PM"
// (a 12-hour clock, hh:mm[:ss] with AM or PM right after it). Returns seconds and the period after which the
// clock wraps (an hour or a day).
std::optional<std::pair<double, double>> parse_clock(std::string_view text);

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
std::vector<TimeDrop> time_order_drops(std::span<const double> t);

// A logger that restarted and counts its time from the start again (or a second drive appended to the file,
// a clock set back): its rows, and those after them, are put on so that its first row comes kRestartGap
// after the last row before it (a new drive; counted in SampleLog::restarts). Its first row is one
// - after a header repeated mid-file (LineReader::restarts, the lines of the repeats) whose time lies
//   behind the last row's (a repeat whose times go on is left as it is), or
// - whose time and the next row's lie more than kClockReset behind the two rows before it, each pair in
//   order: a drive is two rows at least, and a single row out of place (ahead or behind: a corrupt cell) is
//   left to time_order_drops().
// Rows in file order: line(i) their lines, time(i) a reference to their times (in seconds). Returns the
// rows that begin a drive, in order.
template <class Line, class Time>
std::vector<std::size_t> join_restarts(std::size_t n, const std::vector<std::size_t>& restarts, Line line,
                                       Time time, SampleLog& log) {
  std::vector<std::size_t> starts;
  auto repeat = restarts.begin();
  double offset = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    bool after_repeat = false;
    for (; repeat != restarts.end() && *repeat < line(i); ++repeat)
      after_repeat = true;
    double& t = time(i);
    // time(i - 1) and time(i - 2) are put on already, t and time(i + 1) not yet.
    const bool reset = i >= 2 && i + 1 < n && time(i - 2) <= time(i - 1) && t <= time(i + 1) &&
                       time(i + 1) + offset < time(i - 2) - kClockReset;
    if (i > 0 && ((after_repeat && t + offset < time(i - 1)) || reset)) {
      offset = time(i - 1) + kRestartGap - t;
      ++log.restarts;
      starts.push_back(i);
    }
    t += offset;
  }
  return starts;
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
// as skipped and returns false. A log most of whose rows go back in time (written newest first) is refused
// naming `file`: read on, it kept one row and was fitted as a log with nothing to learn from.
class TimeOrder {
 public:
  template <class Rows, class Time>
  TimeOrder(const Rows& rows, Time time, std::string_view file) {
    std::vector<double> t;
    t.reserve(rows.size());
    for (const auto& r : rows)
      t.push_back(time(r));
    drops_ = time_order_drops(t);
    if (t.size() >= 3 && 2 * drops_.size() > t.size())
      throw SampleFileError(std::string(file) + ": " + std::to_string(drops_.size()) + " of " +
                            std::to_string(t.size()) +
                            " rows go back in time (the first: " + drops_.front().reason +
                            "): written newest first? Sort the log by time, oldest first");
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

// Numbers written with thousands separators, as a spreadsheet formats them. Where the point is the decimal
// mark, a comma reaches a cell only inside quotes in a comma-delimited file, where it may be either: a cell
// of comma groups (a sign, one to three digits not starting with 0, then groups of a comma and three
// digits, then perhaps a point and digits: "1,200", "12,345.5") reads as its number where its column says
// the comma groups: another cell of it is a number without a comma, and none has a decimal comma (digits,
// one comma, digits, not groups: "12,5", "0,950"). Where the comma is the decimal mark (LineReader), point
// groups with a decimal comma or more than one point ("1.234,5", "1.234.567") can be nothing else and read;
// one point and three digits ("1.200") read as a decimal point, as any point there, but in a column with
// decimal commas, where it is likely thousands, are a bad row. The column is known once all its cells are
// read: read() takes each, problem() then says which rows hold a cell their column does not vouch for.
class DigitGroups {
 public:
  explicit DigitGroups(const LineReader& reader) : reader_(reader) {}
  // parse_cell(cell, column) of a cell of the reader's record, but digit groups read as their number
  // (unless bad without their separators), kept to be judged with their column. Rows come in line order.
  Cell read(std::string_view cell, std::string_view column);
  // Why the row at `line` holds digit groups its column does not vouch for, or nothing.
  [[nodiscard]] std::optional<std::string> problem(std::size_t line) const;
  [[nodiscard]] bool any() const noexcept { return !grouped_.empty(); }
  // Drops and reports the rows (in line order, each with its `line`) problem() finds.
  template <class Row>
  void drop_unvouched(std::vector<Row>& rows, LogBuilder& out) const {
    if (!any()) return;
    std::erase_if(rows, [&](const Row& r) {
      const auto why = problem(r.line);
      if (why) out.skip(r.line, *why);
      return why.has_value();
    });
  }

 private:
  struct Column {
    std::string name;
    std::size_t plain = 0, decimal_comma = 0;  // cells read as numbers without a comma; cells like "12,5"
  };
  struct Grouped {
    std::size_t line, column;
    std::string text;
    bool points;  // "1.200" where the comma is the decimal mark (else comma groups)
  };
  const LineReader& reader_;
  std::vector<Column> columns_;
  std::vector<Grouped> grouped_;  // in line order
};

inline bool blank(std::string_view line) {
  return trim(line).empty();
}

std::string cells_problem(std::size_t have, std::size_t need);

// A column name folded for matching: lower case, no spaces or underscores.
std::string folded(std::string_view name);
// The same into `out` (its storage reused).
void fold(std::string_view name, std::string& out);

// Whether a line is one of a Freematics logger's, which writes no table but `ms:PID=value` lines
// (`40620:10D=12`: the time in ms, the PID in hex).
bool freematics_line(std::string_view line) noexcept;

// Whether `text` holds any of `parts`.
bool holds(std::string_view text, std::initializer_list<std::string_view> parts) noexcept;

// Whether a column or PID (folded name) is a summary of the drive (an average, a maximum, a limit) rather
// than the car's speed or rpm at the moment.
bool summary_column(std::string_view name) noexcept;

// ---- Units (core/log_units.cpp) ----

// The m/s per unit of the speed unit a column's name (folded) states, or 0.
double stated_speed_to_ms(std::string_view name) noexcept;

// A reading written with its unit after the number, as python-OBD writes a quantity (`790.5
// revolutions_per_minute`, `12.0 kilometer_per_hour`): the number's text and the unit as these readers name
// it ("rpm", "km/h", "mph", "m/s", "knots"). None for any other cell.
struct Quantity {
  std::string_view number, unit;
};
std::optional<Quantity> quantity_cell(std::string_view cell) noexcept;

// A cell written as a quantity in `unit` (named as Quantity::unit names it) is its number; any other cell
// stays as written (a quantity in another unit is then no number).
std::string_view number_in_unit(std::string_view cell, std::string_view unit) noexcept;

// A `speed,rpm` log's speed names no unit and is read as km/h, unless its values tell another: the OBD
// speed (SAE J1979 PID 0x0D) is one byte of whole km/h, so a logger that converts it to mph or m/s writes
// whole km/h in that unit (8.70106 mph is 14 km/h). The unit whose 1 km/h step every moving speed is a whole
// multiple of, over at least ten distinct speeds, one of them not a whole number as written (whole
// numbers are km/h themselves); else km/h. Simulated, logs of 12 speeds in km/h at one, two or six decimals
// (10-135 km/h) were never taken for mph or m/s in 100,000 each, and mph (four conversion factors) and m/s
// written at two decimals or more were always told.
SpeedUnit unit_told_by_values(std::span<const double> speeds);

// The seconds per unit of a time column, from its folded name (time, timestamp, seconds, t or ts; in
// milliseconds when it ends in ms, (ms) or [ms]), or 0 when the name is not a time's.
double time_unit(std::string_view folded_name);

// A clock of the time of day wraps every hour (mm:ss) or day (hh:mm:ss): the rows' times (Row::clock,
// Row::period, from parse_clock) are unwrapped in file order into Row::t.
// A clock cell that jumps away from the row before it while the row after it goes on from that one is
// corrupt: its row is skipped, and its jump is not taken for a wrap (one such cell, "45:00" among "10:0x",
// put every later row an hour on).
template <typename Row>
inline void unwrap_clock(std::vector<Row>& rows, LogBuilder& out) {
  constexpr double kJump = 60.0;  // s: a log's rows are a second or so apart; more is a pause or corrupt
  const auto apart = [](double a, double b, double period) {
    const double d = std::abs(a - b);
    return std::min(d, period - d);  // either way round the clock
  };
  double offset = 0.0, last = -1.0;
  std::size_t kept = 0;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    Row& r = rows[i];
    // The first row has none before it: it is corrupt when it lies away from the two after it, which agree.
    if (i == 0 && rows.size() >= 3 && apart(rows[1].clock, r.clock, r.period) > kJump &&
        apart(rows[2].clock, rows[1].clock, r.period) <= kJump) {
      out.skip(r.line, "time jumps away from the rows after it");
      continue;
    }
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

// ---- The readers of OBD and Torque layouts (core/obd_logs.cpp, core/torque_logs.cpp) ----

// Where an OBD log's values are: its columns, the speed's unit and the time's.
struct ObdLayout {
  SampleFileFormat format = SampleFileFormat::kSpeedRpm;
  std::size_t rpm = 0, speed = 0;
  std::optional<std::size_t> time;  // none: the row counter times ReadOptions::row_seconds
  // The unit the speed column is read in (SampleLog::speed_unit in a named log); none in a speed,rpm log
  // read in the unit its values tell (unit_told_by_values()).
  std::optional<SpeedUnit> speed_in;
  double time_to_s = 1.0;
  std::string speed_column;
  bool quantities = false;  // the rpm and speed cells may carry their unit after the number (quantity_cell)
  std::string_view speed_unit_stated_in = {};  // SampleLog::speed_unit_stated_in
};

// A named-column log's layout (core/obd_logs.cpp says how columns are found): none when the header has no
// rpm or no speed column. A speed column that states no unit is read in `given_unit`
// (ReadOptions::speed_unit) when no column that states one is there; without it, throws SampleFileError
// when the only speed column states no unit.
std::optional<ObdLayout> named_layout(const std::vector<std::string>& header, TorqueSpeed choice,
                                      std::optional<SpeedUnit> given_unit, const std::string& name);

// Carloop, `speed,rpm` and named-column logs, laid out as `layout` says.
void read_obd(LineReader& reader, LogBuilder& out, const ObdLayout& layout);

// Logs of one reading per row (SECONDS, PID, VALUE, UNITS).
void read_pid_rows(LineReader& reader, const std::vector<std::string>& header, LogBuilder& out,
                   TorqueSpeed choice);

// Whether a header is a Torque Pro export's: its rpm column and one of its speed columns (another app that
// names its rpm column as Torque does is read by named_layout()).
[[nodiscard]] bool torque_header(const std::vector<std::string>& header);

// Torque Pro exports.
void read_torque(LineReader& reader, const std::vector<std::string>& header, LogBuilder& out,
                 TorqueSpeed choice);

// Whether a Torque speed column (SampleLog::speed_column of a Torque log) is a GPS one.
[[nodiscard]] bool torque_gps_column(std::string_view column) noexcept;

}  // namespace gearpulse::log_reading
