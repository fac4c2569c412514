#pragma once
// Readers (and a writer) for sample logs: the generic CSV of docs/interfaces.md (`t,speed,freq`), Torque Pro
// exports, Carloop OBD-II logs and `speed,rpm[,...]` logs. The format is detected from the header.
// Parsing works on a stream plus a display name (used in messages): core never opens files.
//
// Units on output are always those of `Sample`: t in s, speed in m/s, freq in Hz (rpm / 60 for OBD logs).
// Rows that cannot be used (garbage, NaN, negative values, time going backwards, too few cells) are
// skipped and reported as "name:line: reason"; a log with no usable sample is an error.
#include <cstddef>
#include <iosfwd>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "core/sample.hpp"

namespace gearpulse {

// The layout of a driving log file: which one read_samples found (SampleLog::format).
// kColumns: another OBD app's or data set's log, its rpm, speed and time columns found by their names;
// kPidRows: one reading per row (SECONDS, PID, VALUE, UNITS), as phone OBD apps export.
enum class SampleFileFormat { kGeneric, kTorque, kCarloop, kSpeedRpm, kColumns, kPidRows };

[[nodiscard]] std::string_view format_name(SampleFileFormat format) noexcept;

// Which speed a log with both gives (Torque Pro exports, named-column and PID-row logs; the name is the
// first of them). kAuto takes the GPS Doppler speed when the file has any (it is what the daemon sees live
// from gpsd, so a model fitted on it matches the live input), else the OBD speed (the car's own
// wheel-speed reading: smoother but quantised and often a few % high).
enum class TorqueSpeed { kAuto, kGps, kObd };

// A unit a speed column is read in: m/s per unit and its name (km/h, mph, m/s or knots), as `--speed-unit`
// takes it and SampleLog::speed_unit says it.
struct SpeedUnit {
  double to_ms = 0.0;
  std::string_view name;
};

// The unit named exactly km/h, mph, m/s or knots; none for any other text.
[[nodiscard]] std::optional<SpeedUnit> speed_unit_named(std::string_view name) noexcept;

struct ReadOptions {
  TorqueSpeed torque_speed = TorqueSpeed::kAuto;
  std::size_t max_messages = 1000;  // skip messages kept (all are counted)
  bool keep_rows = false;           // fill SampleLog::rows (`gearpulse replay` answers every row)
  // Logs without a time column (`speed,rpm`, a Carloop log without its run time): seconds between rows,
  // the row counter's unit. Must be finite and > 0.
  double row_seconds = 1.0;
  // The unit of a speed column whose name (and units row, and cells) states none: a named-column log's,
  // refused without it, and a `speed,rpm` log's, told by its values without it. A column that states its
  // unit keeps it; the generic log's speed is m/s, Torque's, Carloop's and PID rows' state theirs.
  std::optional<SpeedUnit> speed_unit;
};

// One data row the reader accepted: its time and the sample that carries its values. An OBD row that
// only repeats held values has no sample of its own and shares the one it repeats.
struct InputRow {
  double t = 0.0;
  std::size_t sample = 0;
};

// The pause put between a logger's restarts in one file (SampleLog::restarts): ten minutes, beyond every
// gap the logs' users bridge, so that no pair, lag, outage or habit spans it: the synthesis forgets the
// speed after 30 s (SynthTuning::max_gap, ImmSpeedSynthesizer::kMaxGap), the fit pairs rows at most 5 s
// apart (and three median row steps in its lag search), a clock's jump is 60 s (unwrap_clock), a driver's
// habits average over 600 s.
inline constexpr double kRestartGap = 600.0;  // s

// A clock that falls back by more than this without a header repeated is a new drive (SampleLog::restarts),
// not rows out of order. Rows a logger wrote out of order are a sample or two: at most two row steps, and
// the slowest logs read step 1.8 s (a Carloop counter's refresh), under 4 s. And the costs of misreading
// either way meet here: rows behind the last one kept are dropped, as much driving as the fall, where a new
// drive loses only what would span its place, no more than the 5 s over which the fit pairs rows.
inline constexpr double kClockReset = 5.0;  // s

struct SampleLog {
  std::string name;
  SampleFileFormat format = SampleFileFormat::kGeneric;
  std::string speed_column;  // header of the column the speed came from (a PID-row log: the PID's name)
  // A speed,rpm or named-column log's: the unit its speed column was read in (SpeedUnit::name). The one its
  // name, units row or cells state; else ReadOptions::speed_unit; else a speed,rpm log's is km/h, or mph or
  // m/s when every value is whole km/h in that unit (an OBD speed converted by the logger).
  std::string speed_unit;
  // Where a named-column log's speed column, its name stating no unit, states speed_unit: "its units row"
  // (a row of units under the header) or "its cells" (readings written with their units); else empty.
  std::string speed_unit_stated_in;
  std::vector<Sample> samples;
  std::vector<std::string> skipped;  // "name:line: reason", at most ReadOptions::max_messages
  std::size_t skipped_count = 0;     // every skipped bad row
  std::size_t repeated_rows = 0;     // OBD rows dropped because nothing was refreshed (not errors)
  std::vector<InputRow> rows;        // with ReadOptions::keep_rows: every accepted row, in file order
  bool time_from_rows = false;       // no time column: t is the row counter times ReadOptions::row_seconds
  // Places where the time starts again (from 0, or back): after a header repeated mid-file, or falling back
  // by more than kClockReset without one: a logger that restarted, a second drive appended, a clock set
  // back. Each begins a new drive, its times put kRestartGap after the last row before it
  // (log_reading::join_restarts()).
  std::size_t restarts = 0;
  // "name: ..." lines for a log that reads but looks wrong (a generic log's speed in km/h, its time in ms).
  std::vector<std::string> warnings;
};

// Thrown when nothing usable can be read (empty stream, unknown header, no valid row). what() is one
// line that starts with the display name.
struct SampleFileError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

[[nodiscard]] SampleLog read_samples(std::istream& in, std::string_view name,
                                     const ReadOptions& options = {});

// For a Torque Pro export whose speed `log` read from GPS: the same export's rows with the car's OBD
// (wheel) speed instead, read from `in` (the same file again); nothing when `log` is not such an export or
// the export has no usable OBD speed. Bad rows were reported by the first reading.
[[nodiscard]] std::optional<SampleLog> read_wheel_speed(std::istream& in, const SampleLog& log);

// Writes the generic CSV (`t,speed,freq`, empty cell = missing) with enough digits to round-trip.
void write_samples(std::ostream& out, std::span<const Sample> samples);

}  // namespace gearpulse
