// The Torque Pro export reader.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iterator>

#include "core/log_reading.hpp"

namespace gearpulse::log_reading {
namespace {

struct SpeedColumn {
  const char* header;
  double to_ms;
  bool gps;
};
constexpr SpeedColumn kTorqueSpeeds[] = {
    {"GPS Speed (Meters/second)", 1.0, true}, {"Speed (GPS)(km/h)", kKmhToMs, true},
    {"GPS Speed (km/h)", kKmhToMs, true},     {"Speed (GPS)(mph)", kMphToMs, true},
    {"Speed (OBD)(km/h)", kKmhToMs, false},   {"Speed (OBD)(mph)", kMphToMs, false}};

}  // namespace

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
  DigitGroups groups(reader);
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
    const Cell rpm = groups.read(cells[irpm], header[irpm]);
    Cell gps, obd;
    if (igps) gps = groups.read(cells[*igps], header[*igps]);
    if (iobd) obd = groups.read(cells[*iobd], header[*iobd]);
    const Cell* bad = rpm.kind == CellKind::kBad ? &rpm : gps.kind == CellKind::kBad ? &gps : &obd;
    if (bad->kind == CellKind::kBad) {
      out.skip(reader.number, bad->problem);
      continue;
    }
    row.freq = rpm.value / kSecondsPerMinute;
    if (igps) row.gps = gps.value * gps_col->to_ms;
    if (iobd) row.obd = obd.value * obd_col->to_ms;
    rows.push_back(row);
  }
  groups.drop_unvouched(rows, out);
  const auto gps_count = static_cast<std::size_t>(
      std::count_if(rows.begin(), rows.end(), [](const Row& r) { return std::isfinite(r.gps); }));
  if (itime) unwrap_clock(rows, out);
  join_restarts(
      rows.size(), reader.restarts, [&](std::size_t i) { return rows[i].line; },
      [&](std::size_t i) -> double& { return rows[i].t; }, out.log());
  const bool use_gps = choice == TorqueSpeed::kGps || (choice == TorqueSpeed::kAuto && gps_count > 0);
  if (!use_gps && !iobd)
    throw SampleFileError(out.log().name +
                          ":1: no speed values (no OBD speed column and no GPS speed value)");
  out.log().speed_column = use_gps ? gps_col->header : obd_col->header;
  // Times count from the first row kept (a first row dropped for a corrupt time would shift them all).
  TimeOrder order(
      rows, [](const Row& r) { return r.t; }, out.log().name);
  std::optional<double> t0;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    if (!order.keep(i, r.line, out)) continue;
    if (!t0) t0 = r.t;
    out.add(r.line, Sample{r.t - *t0, use_gps ? r.gps : r.obd, r.freq});
  }
}
bool torque_header(const std::vector<std::string>& header) {
  return find_column(header, "Engine RPM(rpm)") &&
         std::any_of(std::begin(kTorqueSpeeds), std::end(kTorqueSpeeds),
                     [&](const SpeedColumn& c) { return find_column(header, c.header).has_value(); });
}

bool torque_gps_column(std::string_view column) noexcept {
  return std::any_of(std::begin(kTorqueSpeeds), std::end(kTorqueSpeeds),
                     [&](const SpeedColumn& c) { return c.gps && column == c.header; });
}

}  // namespace gearpulse::log_reading
