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

#include "core/log_reading.hpp"

namespace gearpulse {

using namespace log_reading;

namespace {

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
  DigitGroups groups(reader);
  while (reader.next_row(cells, need, out)) {
    const Cell t = groups.read(cells[it], "t");
    const Cell v = groups.read(cells[is], "speed");
    const Cell f = groups.read(cells[iff], "freq");
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
  if (groups.any()) {
    std::size_t kept = 0;
    for (std::size_t i = 0; i < rows.size(); ++i) {
      if (const auto problem = groups.problem(lines[i])) {
        out.skip(lines[i], *problem);
        continue;
      }
      lines[kept] = lines[i];
      rows[kept++] = rows[i];
    }
    lines.resize(kept);
    rows.resize(kept);
  }
  join_restarts(
      rows.size(), reader.restarts, [&](std::size_t i) { return lines[i]; },
      [&](std::size_t i) -> double& { return rows[i].t; }, out.log());
  TimeOrder order(
      rows, [](const Sample& r) { return r.t; }, out.log().name);
  for (std::size_t i = 0; i < rows.size(); ++i)
    if (order.keep(i, lines[i], out)) out.add(lines[i], rows[i]);
}

// Whether a header names a column a log is read by: one whose name holds "rpm" or "speed", or a PID-row
// log's PID and VALUE.
bool names_a_log(const std::vector<std::string>& header) {
  return std::any_of(header.begin(), header.end(),
                     [](const std::string& name) {
                       return holds(folded(name), {"rpm", "speed"});
                     }) ||
         (find_column(header, "PID") && find_column(header, "VALUE"));
}

// The next record that is not blank, split into at most `columns` cells; false at the end.
bool next_record(LineReader& reader, std::size_t columns, std::vector<std::string_view>& cells) {
  while (reader.next())
    if (!blank(reader.line)) {
      reader.cells(cells, columns);
      return true;
    }
  return false;
}

// A row of units right under the header (`Time,Engine speed,Speed` then `s,rpm,km/h`, as data loggers write
// it): no cell a number, a speed unit among them. Each unit joins its column's name ("Speed (km/h)"). A
// record that is no such row is left to the reader.
bool read_units_row(LineReader& reader, std::vector<std::string>& header) {
  std::vector<std::string_view> cells;
  reader.look_ahead();
  if (!next_record(reader, header.size(), cells)) {
    reader.rewind();
    return false;
  }
  const bool units =
      std::none_of(cells.begin(), cells.end(),
                   [](std::string_view c) { return parse_cell(c, "").kind == CellKind::kNumber; }) &&
      std::any_of(cells.begin(), cells.end(),
                  [](std::string_view c) { return stated_speed_to_ms(folded(c)) > 0.0; });
  if (!units) {
    reader.rewind();
    return false;
  }
  reader.take();
  for (std::size_t i = 0; i < cells.size(); ++i)
    if (!cells[i].empty()) header[i] += " (" + std::string(cells[i]) + ")";
  return true;
}

// Whether the data rows write readings with their units (quantity_cell(): `12.0 kilometer_per_hour`, as
// python-OBD loggers write them). A speed column whose name states no unit takes the one its first reading
// writes ("SPEED (km/h)"): its first cell that is a quantity or a number (a number states none), passing
// over missing readings (python-OBD writes None or N/A for a PID the car did not answer) within the first
// kLookAhead rows. The rows are left to the reader.
bool quantity_cells(LineReader& reader, std::vector<std::string>& header) {
  // A logger polls a PID the car does not answer at every row: a speed missing this long is none the car
  // gives (at one row a second, over a minute and a half).
  constexpr std::size_t kLookAhead = 100;  // rows
  std::vector<std::size_t> unstated;       // speed columns whose name states no unit, their reading unseen
  for (std::size_t i = 0; i < header.size(); ++i)
    if (const std::string name = folded(header[i]); holds(name, {"speed"}) && stated_speed_to_ms(name) == 0.0)
      unstated.push_back(i);
  bool any = false;
  std::vector<std::string_view> cells;
  reader.look_ahead();
  for (std::size_t rows = 0;
       rows < kLookAhead && (!any || !unstated.empty()) && next_record(reader, header.size(), cells);
       ++rows) {
    any = any || std::any_of(cells.begin(), cells.end(),
                             [](std::string_view c) { return quantity_cell(c).has_value(); });
    std::erase_if(unstated, [&](std::size_t i) {
      if (i >= cells.size()) return false;
      if (const std::optional<Quantity> q = quantity_cell(cells[i])) {
        if (stated_speed_to_ms(q->unit) > 0.0) header[i] += " (" + std::string(q->unit) + ")";
        return true;
      }
      return parse_cell(cells[i], "").kind == CellKind::kNumber;
    });
  }
  reader.rewind();
  return any;
}

// named_layout(), or when it finds no speed with a unit, named_layout() of the header with its units row; a
// speed column that states no unit in either is read in ReadOptions::speed_unit, if given.
// `quantities`: the cells may write their units (quantity_cells(), which added them to `header`'s names);
// `written`: the header as the log writes it, whose name the speed column keeps.
std::optional<ObdLayout> named_columns(LineReader& reader, std::vector<std::string>& header,
                                       const std::vector<std::string>& written, const ReadOptions& options,
                                       const std::string& name, bool quantities) {
  const TorqueSpeed choice = options.torque_speed;
  std::optional<ObdLayout> layout;
  bool units_row = false;
  try {
    layout = named_layout(header, choice, std::nullopt, name);
  } catch (const SampleFileError&) {
    units_row = read_units_row(reader, header);
    if (!units_row && !options.speed_unit) throw;
    layout = named_layout(header, choice, options.speed_unit, name);
  }
  if (!layout && (units_row = read_units_row(reader, header)))
    layout = named_layout(header, choice, options.speed_unit, name);
  if (!layout) return layout;
  layout->quantities = quantities;
  if (header[layout->speed] != written[layout->speed]) {
    layout->speed_column = written[layout->speed];
    layout->speed_unit_stated_in = units_row ? "its units row" : "its cells";
  }
  return layout;
}

}  // namespace

std::optional<SpeedUnit> speed_unit_named(std::string_view name) noexcept {
  for (const SpeedUnit& unit : kSpeedUnits)
    if (unit.name == name) return unit;
  return std::nullopt;
}

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
  LineReader reader(in, name);
  LogBuilder out(name, options);
  // Before the header: blank lines, comment lines ('#') and a spreadsheet's "sep=;" line, which sets the
  // delimiter. False at the end.
  std::optional<char> stated_delimiter;
  const auto next_header = [&] {
    while (reader.next()) {
      const std::string_view line = trim(reader.line);
      if (reader.number == 1 && (line.starts_with("\xFF\xFE") || line.starts_with("\xFE\xFF")))
        throw SampleFileError(std::string(name) + ":1: UTF-16 text: save the log as UTF-8 or ASCII text");
      // "sep=;", spaces or quotes around it aside: the character after the '=' is the delimiter, a tab or a
      // space too (which trimming took off the line: it is read from the untrimmed one).
      if (!stated_delimiter && line.starts_with("sep=") && line.size() <= 5) {
        const std::size_t at = static_cast<std::size_t>(line.data() - reader.line.data()) + 4;
        if (line.size() == 5 ||
            (at < reader.line.size() && std::isspace(static_cast<unsigned char>(reader.line[at])))) {
          stated_delimiter = reader.line[at];
          continue;
        }
      }
      // "#,Time,..." is a header naming its row-number column "#", not a comment: '#' and the delimiter (the
      // one stated by "sep=", or one the header may be split on).
      const std::string_view delimiters =
          stated_delimiter ? std::string_view(&*stated_delimiter, 1) : std::string_view(",;\t");
      const bool comment =
          line.starts_with('#') && (line.size() == 1 || delimiters.find(line[1]) == std::string_view::npos);
      if (!line.empty() && !comment) return true;
    }
    return false;
  };
  // Lines of an app's notes on the drive (a title, a date, the car) may come before the header: a line
  // that names no speed or rpm column, when one that does follows within this many lines.
  constexpr std::size_t kMaxNotes = 32;
  std::vector<std::string> header;
  std::string header_line;  // for the error below: the first line taken for the header
  std::size_t header_number = 0;
  for (std::size_t notes = 0;; ++notes) {
    if (!next_header()) {
      if (in.bad()) throw SampleFileError(std::string(name) + ": read error");
      if (notes == 0) throw SampleFileError(std::string(name) + ": empty file");
      header.clear();  // notes alone: the first line is the unrecognised header
      break;
    }
    std::vector<std::string_view> views;
    if (stated_delimiter)
      reader.set_delimiter(*stated_delimiter);
    else
      reader.detect_delimiter();
    const bool narrow = reader.cells(views, kMaxColumns);
    if (!narrow && notes == 0)
      throw SampleFileError(std::string(name) + ":" + std::to_string(reader.number) +
                            ": header has more than " + std::to_string(kMaxColumns) + " columns");
    header.assign(views.begin(), views.end());
    if (notes == 0) {
      header_line = reader.line;
      header_number = reader.number;
    }
    if (narrow && names_a_log(header)) {
      header_line = reader.line;
      header_number = reader.number;
      break;
    }
    if (notes + 1 == kMaxNotes) {
      header.clear();
      break;
    }
    reader.forget_delimiter();
  }
  reader.set_header(header);
  const auto has = [&](std::string_view column) { return find_column(header, column).has_value(); };

  // The generic header first: its further columns are ignored, whatever their names. The other apps' logs
  // may write their readings with units (quantity_cells()): a speed's makes it a named-column log.
  const bool generic = has("t") && has("speed") && has("freq");
  const bool carloop_header = has("ENGINE_RPM ()") && has("VEHICLE_SPEED ()");
  const bool torque = !generic && torque_header(header);
  const std::vector<std::string> written = header;  // the names as written, before units found are added
  const bool quantities = !generic && !torque && !carloop_header && quantity_cells(reader, header);
  if (generic) {
    read_generic(reader, header, out);
  } else if (torque) {
    read_torque(reader, header, out, options.torque_speed);
  } else if (carloop_header) {
    ObdLayout carloop{SampleFileFormat::kCarloop,
                      *find_column(header, "ENGINE_RPM ()"),
                      *find_column(header, "VEHICLE_SPEED ()"),
                      find_column(header, "ENGINE_RUN_TINE ()"),
                      kKmh,
                      1.0,
                      "VEHICLE_SPEED ()"};  // sic: the logger's own spelling, RUN_TINE
    if (!carloop.time) carloop.time = find_column(header, "ENGINE_RUN_TIME ()");
    read_obd(reader, out, carloop);
  } else if (header.size() >= 2 && has("speed") && has("rpm")) {
    ObdLayout layout{SampleFileFormat::kSpeedRpm,
                     *find_column(header, "rpm"),
                     *find_column(header, "speed"),
                     std::nullopt,
                     options.speed_unit,  // none: the unit its values tell
                     1.0,
                     "speed"};
    layout.quantities = quantities;
    for (std::size_t i = 0; i < header.size() && !layout.time; ++i)  // a time column, as named columns'
      if (const double to_s = time_unit(folded(header[i])); to_s > 0.0) {
        layout.time = i;
        layout.time_to_s = to_s;
      }
    read_obd(reader, out, layout);
  } else if (has("SECONDS") && has("PID") && has("VALUE")) {
    read_pid_rows(reader, header, out, options.torque_speed);
  } else if (auto layout = named_columns(reader, header, written, options, std::string(name), quantities)) {
    read_obd(reader, out, *layout);
  } else if (has("Engine RPM(rpm)")) {
    read_torque(reader, header, out, options.torque_speed);  // an export without speed: its own error
  } else {
    // A log of the car that lacks one of the two columns the fit needs is named for it: the user's fix is
    // to log that reading, not to rename columns.
    const auto names = [&](std::string_view part) {
      return std::any_of(header.begin(), header.end(),
                         [&](const std::string& column) { return holds(folded(column), {part}); });
    };
    const char* lacks = "";
    if (names("speed") && !names("rpm"))
      lacks = ": no column's name holds 'rpm' (the engine speed): log the engine RPM as well";
    else if (names("rpm") && !names("speed"))
      lacks = ": no column's name holds 'speed' (the vehicle's, with its unit): log the speed as well";
    if (freematics_line(header_line))
      lacks =
          ": a Freematics log (ms:PID=value lines), which is not read: write its PIDs 10C (rpm) and 10D "
          "(speed, km/h) as columns time (ms),rpm,speed (km/h)";
    throw SampleFileError(
        std::string(name) + ":" + std::to_string(header_number) + ": unrecognised header " +
        quoted(header_line) + lacks +
        " (expected t,speed,freq, a Torque Pro, Carloop or speed,rpm log, SECONDS,PID,VALUE "
        "rows, or columns named rpm and speed with a unit)");
  }
  if (in.bad()) throw SampleFileError(std::string(name) + ": read error");
  SampleLog log = out.finish();
  if (log.format == SampleFileFormat::kGeneric) warn_units(log);
  return log;
}

std::optional<SampleLog> read_wheel_speed(std::istream& in, const SampleLog& log) {
  if (log.format != SampleFileFormat::kTorque || !log_reading::torque_gps_column(log.speed_column))
    return std::nullopt;
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
