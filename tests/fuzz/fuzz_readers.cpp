// Fuzz target for the log readers (core/sample_io): whatever the bytes, read_samples returns a log whose
// times are finite and never run backwards and whose values are in range, or throws SampleFileError; the
// wheel-speed reader holds the same; and what write_samples writes reads back identically. The first byte
// picks the options (Torque speed column, keep_rows, the message cap, the row spacing of logs without
// times, the unit of a speed column that states none).
#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>

#include "core/sample_io.hpp"
#include "tests/fuzz/fuzz_check.hpp"

using namespace gearpulse;

namespace {

bool same(double a, double b) {
  return (std::isnan(a) && std::isnan(b)) || a == b;
}

void check_log(const SampleLog& log, const ReadOptions& opt) {
  FUZZ_CHECK(!log.samples.empty());
  FUZZ_CHECK(log.skipped.size() <= opt.max_messages);
  FUZZ_CHECK(log.skipped_count >= log.skipped.size());
  for (std::size_t i = 0; i < log.samples.size(); ++i) {
    const Sample& s = log.samples[i];
    FUZZ_CHECK(std::isfinite(s.t));
    if (i > 0) FUZZ_CHECK(s.t >= log.samples[i - 1].t);
    FUZZ_CHECK(std::isnan(s.speed) || (s.speed >= 0.0 && s.speed <= 150.0));
    FUZZ_CHECK(std::isnan(s.freq) || (s.freq >= 0.0 && s.freq <= 20000.0));
  }
  for (std::size_t i = 0; i < log.rows.size(); ++i) {
    FUZZ_CHECK(log.rows[i].sample < log.samples.size());
    FUZZ_CHECK(std::isfinite(log.rows[i].t));
    if (i > 0) FUZZ_CHECK(log.rows[i].t >= log.rows[i - 1].t);
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  ReadOptions opt;
  const std::uint8_t options = data[0];
  opt.torque_speed = static_cast<TorqueSpeed>(options % 3);
  opt.keep_rows = ((options >> 2) & 1) != 0;
  opt.max_messages = ((options >> 3) & 1) != 0 ? 3 : 1000;
  constexpr double kRowSeconds[] = {1.0, 2.0, 0.1, 3600.0};
  opt.row_seconds = kRowSeconds[(options >> 4) & 3];
  constexpr const char* kGivenUnits[] = {"", "mph", "km/h", "knots"};  // "": none given
  opt.speed_unit = speed_unit_named(kGivenUnits[(options >> 6) & 3]);
  const std::string text(reinterpret_cast<const char*>(data + 1), size - 1);
  SampleLog log;
  try {
    std::istringstream in(text);
    log = read_samples(in, "fuzz", opt);
  } catch (const SampleFileError&) {
    return 0;
  }
  check_log(log, opt);
  {
    std::istringstream in(text);
    if (const auto wheel = read_wheel_speed(in, log)) check_log(*wheel, ReadOptions{});
  }
  std::ostringstream out;
  write_samples(out, log.samples);
  std::istringstream back(out.str());
  SampleLog again;
  try {
    again = read_samples(back, "written");
  } catch (const SampleFileError& e) {
    std::fprintf(stderr, "what write_samples wrote does not read back: %s\n", e.what());
    std::abort();
  }
  FUZZ_CHECK(again.samples.size() == log.samples.size());
  for (std::size_t i = 0; i < log.samples.size(); ++i) {
    FUZZ_CHECK(same(again.samples[i].t, log.samples[i].t));
    FUZZ_CHECK(same(again.samples[i].speed, log.samples[i].speed));
    FUZZ_CHECK(same(again.samples[i].freq, log.samples[i].freq));
  }
  FUZZ_CHECK(again.skipped_count == 0);
  return 0;
}
