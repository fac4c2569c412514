// The OBD readers: Carloop logs, `speed,rpm` logs, logs whose columns are found by their names, and logs
// of one reading per row. Each parses its rows into ObdRow and add_obd_rows() keeps what is new.

#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>

#include "core/log_reading.hpp"

namespace gearpulse::log_reading {
namespace {

// The Carloop logger writes rows at a steady rate (it polls its PIDs round-robin) but its run-time
// counter has a resolution of one second and is itself refreshed only once per cycle (~1.8 s). The time of
// a row is therefore estimated from its row number by a local straight-line fit through the points where
// the counter changed (middle of its one-second step), which brings the timing error well below a second.
// The fit stays within a row's drive (`drives`: the counters at which a restart begins one, in order), as
// if each drive were a log of its own.
std::vector<double> smooth_row_times(const std::vector<double>& rows, const std::vector<double>& refresh_row,
                                     const std::vector<double>& refresh_t,
                                     const std::vector<double>& drives) {
  constexpr std::size_t kHalfWindow = 8;  // refresh points each side (~15 s)
  std::vector<double> out(rows.size());
  double previous = -std::numeric_limits<double>::infinity();
  const auto refresh_at = [&](double counter) {
    return static_cast<std::size_t>(std::lower_bound(refresh_row.begin(), refresh_row.end(), counter) -
                                    refresh_row.begin());
  };
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const auto k = refresh_at(rows[i]);
    const auto next = std::upper_bound(drives.begin(), drives.end(), rows[i]);
    const std::size_t first = next == drives.begin() ? 0 : refresh_at(*(next - 1));
    const std::size_t end = next == drives.end() ? refresh_row.size() : refresh_at(*next);
    const std::size_t lo = std::max(first, k > kHalfWindow ? k - kHalfWindow : 0);
    const std::size_t hi = std::min(end, k + kHalfWindow + 1);
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

// One OBD row as read: its line, its place among the data rows, its time, rpm and speed (the log's unit).
struct ObdRow {
  std::size_t line;
  double counter, t, rpm, speed;
  double clock = -1.0, period = 0.0;  // a clock cell's time of day (s) and its wrap (unwrap_clock)
  bool drive_start = false;           // a restart begins a drive here (join_restarts)
};

// OBD values held between refreshes, in file order. A row whose rpm and speed both equal the previous
// row's carries nothing new (a logger polls many PIDs round-robin), so it is dropped (not in PID-row logs).
// Times count from the first row kept but in Carloop logs (the engine's run time).
void add_obd_rows(std::vector<ObdRow>& parsed, LogBuilder& out, const ObdLayout& layout) {
  const SampleFileFormat format = layout.format;
  const bool timed = layout.time.has_value();
  double last_rpm = kMissing, last_speed = kMissing, last_t = -std::numeric_limits<double>::infinity();
  bool have_last = false;
  std::vector<std::size_t> lines;
  std::vector<double> rows, refresh_row, refresh_t, drives;
  std::vector<Sample> kept;
  // Rows repeating held values (kept for SampleLog::rows only): row counter, own time, the kept row.
  struct Repeat {
    double row, t;
    std::size_t of, line;
  };
  std::vector<Repeat> repeats;
  const bool from_first = format != SampleFileFormat::kCarloop && timed;
  // Each reading of a PID-row log is a poll of its own, not a value held by a logger's row.
  const bool held = format != SampleFileFormat::kPidRows;
  std::optional<double> t0;
  TimeOrder order(
      parsed, [](const ObdRow& p) { return p.t; }, out.log().name);
  for (std::size_t i = 0; i < parsed.size(); ++i) {
    if (!order.keep(i, parsed[i].line, out)) continue;
    if (from_first && !t0) t0 = parsed[i].t;
    ObdRow p = parsed[i];
    if (t0) p.t -= *t0;
    if (p.drive_start) {  // a new drive: nothing is held from the last
      drives.push_back(p.counter);
      have_last = false;
    }
    if (p.t != last_t) {
      refresh_row.push_back(p.counter);
      refresh_t.push_back(p.t + 0.5);
    }
    last_t = p.t;
    const auto same = [](double a, double b) { return (std::isnan(a) && std::isnan(b)) || a == b; };
    if (held && have_last && same(p.rpm, last_rpm) && same(p.speed, last_speed)) {
      ++out.log().repeated_rows;
      if (out.keeps_rows()) repeats.push_back({p.counter, p.t, kept.size() - 1, p.line});
      continue;
    }
    last_rpm = p.rpm;
    last_speed = p.speed;
    have_last = true;
    lines.push_back(p.line);
    rows.push_back(p.counter);
    kept.push_back(Sample{p.t, p.speed * layout.speed_in->to_ms, p.rpm / kSecondsPerMinute});
  }
  if (format == SampleFileFormat::kCarloop && timed && refresh_row.size() >= 2) {
    // The counter on a row is the whole second at its last refresh, at most one polling round old: the
    // estimate stays within that (it matters only at the ends of a log, where the fit is one-sided).
    constexpr double kMaxCounterAge = 3.0;  // s: one second of resolution plus a polling round
    const auto estimate = [&](const std::vector<double>& at, auto&& own_t, auto&& set_t) {
      const std::vector<double> times = smooth_row_times(at, refresh_row, refresh_t, drives);
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

// A time cell's number and the digits after its point as written (none: -1, a number with an exponent).
struct TimeWritten {
  double value;
  int decimals;
};

int decimals_written(std::string_view cell) {
  cell = trim(cell);
  if (cell.find_first_of("eE") != std::string_view::npos) return -1;
  const std::size_t point = cell.rfind('.');  // a decimal comma is a point in the line read
  if (point == std::string_view::npos) return 0;
  int digits = 0;
  for (std::size_t i = point + 1; i < cell.size() && std::isdigit(static_cast<unsigned char>(cell[i])); ++i)
    ++digits;
  return digits;
}

// A time since the log's first, in the digits the two are written to: a clock since 1970 in seconds is
// 1.5e9, where a double keeps 2.4e-7 s and the difference of two times written to the millisecond would
// print 1.5989999771118164 for 1.599. Rounded to the finer of the two's decimals, the difference is the
// nearest double to the one written; times from 0 are their own numbers again.
double difference_written(double value, TimeWritten first, int decimals) {
  const double d = value - first.value;
  if (decimals < 0 || first.decimals < 0) return d;
  double scale = 1.0;  // a power of ten is exact up to 1e22
  for (int i = std::max(decimals, first.decimals); i > 0 && scale < 1e22; --i)
    scale *= 10.0;
  constexpr double kExactIntegers = 9007199254740992.0;  // 2^53
  if (!(std::abs(d) * scale < kExactIntegers)) return d;
  return std::round(d * scale) / scale;
}

}  // namespace

// Logs of other OBD apps and data sets, found by their column names (see folded()): the first column
// whose name holds "rpm"; a speed column, whose name holds "speed" and states its unit, a GPS one (its name
// holds "gps") or another as `--speed` asks (auto: GPS when there is one); else one whose name states no
// unit, chosen the same way, read in `given_unit`; a time column named time, timestamp, seconds, t or ts, in
// milliseconds when its name ends in ms, (ms) or [ms]. None when the header has no rpm or no speed column;
// an error naming the column when the only speed has no unit and `given_unit` gives none.
std::optional<ObdLayout> named_layout(const std::vector<std::string>& header, TorqueSpeed choice,
                                      std::optional<SpeedUnit> given_unit, const std::string& name) {
  ObdLayout layout;
  layout.format = SampleFileFormat::kColumns;
  std::optional<std::size_t> rpm, gps, other, unitless_gps, unitless_other;
  for (std::size_t i = 0; i < header.size(); ++i) {
    const std::string f = folded(header[i]);
    if (f.find("rpm") != std::string::npos) {
      if (!rpm && !summary_column(f)) rpm = i;
      continue;
    }
    if (const double to_s = time_unit(f); to_s > 0.0 && !layout.time) {
      layout.time = i;
      layout.time_to_s = to_s;
      continue;
    }
    if (f.find("speed") == std::string::npos || summary_column(f)) continue;
    const bool is_gps = f.find("gps") != std::string::npos;
    std::optional<std::size_t>& column =
        stated_speed_to_ms(f) == 0.0 ? (is_gps ? unitless_gps : unitless_other) : (is_gps ? gps : other);
    if (!column) column = i;
  }
  if (!rpm) return std::nullopt;
  const auto pick = [choice](std::optional<std::size_t> gps_column, std::optional<std::size_t> other_column) {
    if (choice == TorqueSpeed::kAuto) return gps_column ? gps_column : other_column;
    return choice == TorqueSpeed::kGps ? gps_column : other_column;
  };
  std::optional<std::size_t> speed = pick(gps, other);
  const bool stated = speed.has_value();
  if (!speed && given_unit) speed = pick(unitless_gps, unitless_other);
  if (!speed) {
    const bool any_unitless = unitless_gps || unitless_other;
    if (choice != TorqueSpeed::kAuto && (gps || other || (given_unit && any_unitless)))
      throw SampleFileError(name + ":1: no " + (choice == TorqueSpeed::kGps ? "GPS" : "OBD") +
                            " speed column (a name holding 'speed' and a unit" +
                            (choice == TorqueSpeed::kGps ? ", and 'GPS')" : ", without 'GPS')"));
    if (any_unitless)
      throw SampleFileError(name + ":1: speed column " +
                            quoted(header[std::min(unitless_gps.value_or(header.size()),
                                                   unitless_other.value_or(header.size()))]) +
                            " states no unit: name it with km/h, mph, m/s or knots, or pass --speed-unit");
    return std::nullopt;
  }
  layout.rpm = *rpm;
  layout.speed = *speed;
  layout.speed_column = header[*speed];
  if (!stated) {
    layout.speed_in = given_unit;
    return layout;
  }
  const double to_ms = stated_speed_to_ms(folded(header[*speed]));
  for (const SpeedUnit& unit : kSpeedUnits)
    if (unit.to_ms == to_ms) layout.speed_in = unit;
  return layout;
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
  // A time column found by its name (time_unit()): seconds, milliseconds or clock cells.
  const bool named = format == SampleFileFormat::kColumns || format == SampleFileFormat::kSpeedRpm;
  std::vector<std::string_view> cells;
  std::vector<ObdRow> parsed;
  bool milliseconds = false;         // the log's clock counts milliseconds since 1970
  std::optional<TimeWritten> first;  // the first time since 1970 of a row read (not bad), as written
  DigitGroups groups(reader);
  // A cell that writes the column's unit after its number is the number; any other stays as written.
  const auto number_of = [&](std::string_view cell, std::string_view unit) {
    return layout.quantities ? number_in_unit(cell, unit) : cell;
  };
  // A speed,rpm log read in the unit its values tell (found once they are read) takes km/h's quantities.
  const std::string_view speed_cells_unit = layout.speed_in.value_or(kKmh).name;
  while (reader.next_row(cells, need, out)) {
    const auto counter = static_cast<double>(reader.rows - 1);
    double period = 0.0;      // of a clock cell's time of day
    double per_second = 0.0;  // a named log's clock since 1970 in units a second: counted from the first
    const Cell rpm = groups.read(number_of(cells[irpm], "rpm"), "rpm");
    const Cell speed = groups.read(number_of(cells[ispeed], speed_cells_unit), "speed");
    Cell t;
    t.kind = CellKind::kNumber;
    t.value = counter * out.row_seconds();
    if (it) {
      t = groups.read(cells[*it], "time");
      // No log's clock in seconds reaches 1e11 (the year 5138 since 1970): beyond, milliseconds. No
      // drive's running time reaches 1e8 s (three years), which a clock since 1970 passed in 1973: beyond,
      // seconds since 1970. Either counts from the log's first in the digits written (difference_written():
      // 1.5e12 ms made seconds first keep only 2e-7 s); smaller times (from the log's start) stay as
      // written. Once a log counts milliseconds, a smaller time is no time of it.
      constexpr double kSecondsSince1970AtLeast = 1e8;
      constexpr double kMillisecondsAtLeast = 1e11;
      if (t.kind == CellKind::kNumber && named && t.value >= kMillisecondsAtLeast) {
        milliseconds = true;
        per_second = 1000.0;
      } else if (t.kind == CellKind::kNumber && milliseconds) {
        t = Cell{
            CellKind::kBad, kMissing,
            "time " + std::string(trim(cells[*it])) + " is not milliseconds since 1970 as the log's first"};
      } else if (t.kind == CellKind::kNumber && named &&
                 t.value * layout.time_to_s >= kSecondsSince1970AtLeast) {
        per_second = 1.0 / layout.time_to_s;
      } else if (t.kind == CellKind::kNumber) {
        t.value *= layout.time_to_s;
      }
      const auto clock = named && t.kind == CellKind::kBad ? parse_clock(cells[*it]) : std::nullopt;
      if (clock) {
        t = Cell{CellKind::kNumber, clock->first, {}};
        period = clock->second;
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
    if (per_second > 0.0) {
      if (!first) first = {t.value, decimals_written(cells[*it])};
      t.value = difference_written(t.value, *first, decimals_written(cells[*it])) / per_second;
    }
    ObdRow row{reader.number, counter, t.value, rpm.value, speed.value};
    if (period > 0.0) row.clock = t.value, row.period = period;
    parsed.push_back(row);
  }
  groups.drop_unvouched(parsed, out);
  // A time column holds numbers or clock times: the fewer kind are bad cells.
  const auto clock_rows = static_cast<std::size_t>(
      std::count_if(parsed.begin(), parsed.end(), [](const ObdRow& r) { return r.period > 0.0; }));
  if (clock_rows > 0) {
    const bool clocks = 2 * clock_rows >= parsed.size();
    std::erase_if(parsed, [&](const ObdRow& r) {
      if ((r.period > 0.0) == clocks) return false;
      out.skip(r.line, clocks ? "a number among clock times in column time"
                              : "a clock time among numbers in column time");
      return true;
    });
    if (clocks) unwrap_clock(parsed, out);
  }
  for (std::size_t i : join_restarts(
           parsed.size(), reader.restarts, [&](std::size_t i) { return parsed[i].line; },
           [&](std::size_t i) -> double& { return parsed[i].t; }, out.log()))
    parsed[i].drive_start = true;
  out.log().speed_unit_stated_in = layout.speed_unit_stated_in;
  if (layout.speed_in) {
    if (named) out.log().speed_unit = layout.speed_in->name;
    add_obd_rows(parsed, out, layout);
    return;
  }
  std::vector<double> speeds(parsed.size());
  std::transform(parsed.begin(), parsed.end(), speeds.begin(), [](const ObdRow& r) { return r.speed; });
  ObdLayout in_unit = layout;
  in_unit.speed_in = unit_told_by_values(speeds);
  out.log().speed_unit = in_unit.speed_in->name;
  add_obd_rows(parsed, out, in_unit);
}

// One reading per row (`SECONDS;PID;VALUE;UNITS`, as phone OBD apps such as Car Scanner export): the
// engine's rpm (the PID named Engine RPM, else the first whose unit or name is rpm) and a speed (a PID
// whose name holds "speed" but no average or maximum, with a speed unit; GPS or OBD as `--speed` asks,
// auto: GPS when there is one) are read; each rpm reading is a row, with the speed at its time (below). A
// SECONDS clock of the time of day (below 86400 s) that falls back by half a day has passed midnight; any
// other clock that falls back is a new drive or rows out of order (join_restarts).
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
    double to_ms;         // speed unit of the row (0: none; -1: none written, its PID's)
    std::string problem;  // why the value does not read (said only for the PIDs used)
  };
  std::vector<std::string> names;    // folded, for matching
  std::vector<std::string> written;  // as the log writes them
  std::vector<std::string> units;    // of each PID's first reading with a unit, folded
  std::vector<Reading> readings;
  std::vector<std::string_view> cells;
  constexpr double kDay = 86400.0;
  double last_t = -1.0, offset = 0.0;
  DigitGroups times(reader), values(reader);
  while (reader.next_row(cells, need, out)) {
    const Cell t = times.read(cells[it], "time");
    const Cell value = values.read(cells[ivalue], "value");
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
      written.emplace_back(cells[ipid]);
      units.push_back(unit);
    } else if (units[pid].empty()) {
      units[pid] = unit;
    }
    double seconds = t.value >= 1e11 ? t.value * 1e-3 : t.value;  // milliseconds since 1970, as above
    if (last_t >= 0.0 && last_t < kDay && seconds < kDay && seconds < last_t - kDay / 2) offset += kDay;
    last_t = seconds;
    seconds += offset;
    readings.push_back({reader.number, seconds, value.value, pid,
                        unit.empty() ? -1.0 : stated_speed_to_ms(unit), value.problem});
  }
  // Digit groups their column does not vouch for: in a value, a bad value (said for the PIDs used); in the
  // time, a bad row.
  for (Reading& r : readings)
    if (const auto why = values.any() ? values.problem(r.line) : std::nullopt) r.problem = *why;
  times.drop_unvouched(readings, out);
  join_restarts(
      readings.size(), reader.restarts, [&](std::size_t i) { return readings[i].line; },
      [&](std::size_t i) -> double& { return readings[i].t; }, out.log());
  const auto find_pid = [&](auto&& good) -> std::optional<std::size_t> {
    for (std::size_t i = 0; i < names.size(); ++i)
      if (good(i)) return i;
    return std::nullopt;
  };
  std::optional<std::size_t> rpm = find_pid([&](std::size_t i) { return names[i] == "enginerpm"; });
  if (!rpm)
    rpm = find_pid([&](std::size_t i) {
      return (units[i] == "rpm" || holds(names[i], {"rpm"})) && !summary_column(names[i]);
    });
  const auto speed_pid = [&](std::size_t i, bool gps) {
    return holds(names[i], {"speed"}) && !summary_column(names[i]) &&
           stated_speed_to_ms(units[i].empty() ? names[i] : units[i]) > 0.0 &&
           holds(names[i], {"gps"}) == gps;
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
                          " among the PIDs (a PID whose name holds 'speed', in km/h, mph, m/s or knots)");
  ObdLayout layout;
  layout.format = SampleFileFormat::kPidRows;
  layout.time = it;
  layout.speed_in = kMetresPerSecond;  // each reading converted by its own unit
  layout.speed_column = written[*speed];
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
  for (Reading& r : readings) {
    if (r.pid != *rpm && r.pid != *speed) continue;
    if (r.to_ms < 0.0) r.to_ms = stated_speed_to_ms(units[r.pid].empty() ? names[r.pid] : units[r.pid]);
    if (!r.problem.empty()) {
      out.skip(r.line, r.problem);
      continue;
    }
    if (r.pid == *rpm)
      revs.push_back(&r);
    else if (r.to_ms > 0.0)
      speeds.push_back({r.t, r.value * r.to_ms});
    else
      out.skip(r.line, "no speed unit for " + quoted(written[r.pid]));
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

}  // namespace gearpulse::log_reading
