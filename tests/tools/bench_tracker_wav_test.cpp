// `bench_tracker --wav FILE --tacho FILE.csv`: a recording scored against a revs log as a user's OBD app
// writes one (a row every second or so), run as the built binary.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "tests/test_util.hpp"
#include "tools/sim/lighter_signal.hpp"

namespace sim = gearpulse::sim;

using gearpulse::test::TempDir;

namespace {

const std::string kBench = GEARPULSE_BINARY_DIR "/bench/bench_tracker";

struct Result {
  int status = -1;
  std::string out, err;
};

Result run(const TempDir& dir, const std::string& args) {
  const std::string err = (dir / "stderr").string();
  const gearpulse::test::ShellResult s =
      gearpulse::test::run_shell("'" + kBench + "' " + args + " 2>'" + err + "'");
  return {s.status, s.out, gearpulse::test::read_text(err)};
}

// A four-cylinder's firing frequency (Hz) over 16 s: a launch from 33 to 110 Hz, an upshift's fall to 70 Hz
// within 0.3 s, a pull to 120 Hz and a cruise.
double launch(double t) {
  if (t < 4.0) return 33.0 + 19.25 * t;
  if (t < 4.3) return 110.0 - 40.0 * (t - 4.0) / 0.3;
  if (t < 10.0) return 70.0 + 50.0 * (t - 4.3) / 5.7;
  return 120.0;
}

// The recording (8 kHz mono, 10 dB) and its revs (t,rpm, rpm = f x 30 for the default order 2): one row
// every 1.0-1.3 s, as an OBD app polls them, or every `step` s; returns the two paths.
std::pair<std::string, std::string> recording(const TempDir& dir, double step = 0.0) {
  sim::LighterSignalConfig g;
  g.sample_rate_hz = 8000.0;
  g.amplitude = 0.05;
  g.snr_db = 10.0;
  g.seed = 7;
  const auto x = sim::make_lighter_signal(g, launch, 16.0);
  std::string error;
  const std::string wav = (dir / "drive.wav").string();
  REQUIRE(sim::write_wav_pcm16(wav, x, 1, 8000, error));
  const std::string tacho = (dir / "rpm.csv").string();
  std::ofstream out(tacho);
  out << "t,rpm\n";
  const double polls[] = {1.0, 1.3, 1.1, 1.2};
  int i = 0;
  for (double t = 0.0; t <= 16.0; t += step > 0.0 ? step : polls[i++ % 4])
    out << t << ',' << launch(t) * 30.0 << '\n';
  return {wav, tacho};
}

double figure(const std::string& out, const std::string& name) {
  const std::string key = "figure " + name + " = ";
  const std::size_t at = out.find(key);
  return at == std::string::npos ? NAN : std::stod(out.substr(at + key.size()));
}

}  // namespace

TEST_CASE("bench_tracker: scores a recording against revs logged every 0.1 s and every 1.0-1.3 s") {
  if (!std::filesystem::exists(kBench)) GEARPULSE_SKIP_TEST("bench_tracker not built (GEARPULSE_BENCH off)");
  TempDir dir;
  // Revs every 0.1 s: the tracker follows the launch, its upshift and the pull.
  {
    const auto [wav, tacho] = recording(dir, 0.1);
    const Result r = run(dir, "--wav '" + wav + "' --tacho '" + tacho +
                                  "' --require 'in_band_hops>=140' --require 'coverage_pct>=95'"
                                  " --require 'gross_pct<=1' --require 'longest_lock_s<=0.3'");
    INFO(r.out << r.err);
    CHECK(r.status == 0);
    CHECK(r.out.find("interpolated across intervals up to 1.00 s") != std::string::npos);
  }
  // Revs every 1.0-1.3 s: interpolated across (up to 1.5 x the median interval), not left as gaps.
  const auto [wav, tacho] = recording(dir);
  const Result r = run(dir, "--wav '" + wav + "' --tacho '" + tacho +
                                "' --require 'in_band_hops>=140' --require 'coverage_pct>=95'");
  INFO(r.out << r.err);
  CHECK(r.status == 0);
  CHECK(r.out.find("interpolated across intervals up to 1.65 s") != std::string::npos);
  // Interpolated across the upshift's fall, the truth is off where the revs were; the range between the
  // two rows around each hop holds them but where the launch peaked between two rows, so fewer hops count
  // as gross against it.
  CHECK(figure(r.out, "gross_range_pct") < figure(r.out, "gross_pct"));
  CHECK(figure(r.out, "gross_pct") > 1.0);
  CHECK(r.err.empty());
}

TEST_CASE("bench_tracker: no truth in the band, a missed threshold, odd tacho rows and a bad channel") {
  if (!std::filesystem::exists(kBench)) GEARPULSE_SKIP_TEST("bench_tracker not built (GEARPULSE_BENCH off)");
  TempDir dir;
  const auto [wav, tacho] = recording(dir);
  // Intervals of at most 0.9 s interpolated across: none of the log's 1.0-1.3 s, so no hop has a truth.
  const Result none = run(dir, "--wav '" + wav + "' --tacho '" + tacho + "' --tacho-gap 0.9");
  CHECK(none.status == 1);
  CHECK(none.err.find("no hop of") != std::string::npos);
  CHECK(none.err.find("--tacho-gap") != std::string::npos);
  const Result missed = run(dir, "--wav '" + wav + "' --tacho '" + tacho + "' --require 'coverage_pct>=101'");
  CHECK(missed.status == 1);
  CHECK(missed.out.find("FAILED") != std::string::npos);
  // Rows that share a time are one sample; a time going back names its line.
  const std::string shared = (dir / "shared.csv").string(), back = (dir / "back.csv").string();
  std::ofstream(shared) << "t,rpm\n0,1000\n1,2000\n1,2200\n2,2400\n";
  std::ofstream(back) << "t,rpm\n0,1000\n2,2000\n1,1500\n";
  const Result merged = run(dir, "--wav '" + wav + "' --tacho '" + shared + "'");
  CHECK(merged.out.find("3 rows over 0.0-2.0 s") != std::string::npos);
  CHECK(merged.out.find("1 row(s) sharing a time with the row above averaged into it") != std::string::npos);
  const Result backwards = run(dir, "--wav '" + wav + "' --tacho '" + back + "'");
  CHECK(backwards.status == 2);
  CHECK(backwards.err.find("back.csv:4: time 1 is before the row above's 2") != std::string::npos);
  // A spreadsheet's export (semicolons, decimal commas) and a tab-separated log read as the comma one (a
  // comma in them a decimal mark, not a third field); a gap marked "-" is skipped and counted; a file of no
  // rows names its first line.
  const std::string euro = (dir / "euro.csv").string(), tabs = (dir / "tabs.csv").string(),
                    words = (dir / "words.csv").string();
  std::ofstream(euro) << "t;rpm\n0;1000\n1,5;2000,5\n2;-\n3;2400\n";
  std::ofstream(tabs) << "t\trpm\n0\t1000\n1,5\t2000.5\n2\t-\n3\t2400\n";  // decimal commas or points
  std::ofstream(words) << "time,revs\nzero,idle\n";
  std::vector<double> in_band;
  for (const std::string& f : {euro, tabs}) {
    const Result r = run(dir, "--wav '" + wav + "' --tacho '" + f + "'");
    INFO(f << ": " << r.out << r.err);
    CHECK(r.out.find("3 rows over 0.0-3.0 s") != std::string::npos);
    CHECK(r.out.find("2 line(s) not two numbers skipped (first, line 1: 't") != std::string::npos);
    in_band.push_back(figure(r.out, "in_band_hops"));
  }
  CHECK(in_band[0] > 0.0);
  CHECK(in_band[0] == in_band[1]);  // the same revs read from both
  const Result unread = run(dir, "--wav '" + wav + "' --tacho '" + words + "'");
  CHECK(unread.status == 2);
  CHECK(unread.err.find("words.csv: fewer than two t,rpm rows (2 line(s) not two numbers; first, line 1: "
                        "'time,revs')") != std::string::npos);
  const Result channel = run(dir, "--wav '" + wav + "' --tacho '" + tacho + "' --channel 1");
  CHECK(channel.status == 2);
  CHECK(channel.err.find("--channel 1 but the file has 1 channel(s), counted from 0") != std::string::npos);
}
