// `gearpulse track --confidence`: a fourth CSV column and every hop's estimate, trusted or not.
#include <catch2/catch.hpp>

#include <sys/wait.h>

#include <cmath>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

#include "tests/test_util.hpp"
#include "tools/sim/lighter_signal.hpp"

namespace sim = gearpulse::sim;
using gearpulse::test::read_text;
using gearpulse::test::TempDir;

namespace {

struct Row {
  double t = NAN, freq = NAN, snr = NAN, confidence = NAN;
};

// Runs `gearpulse track ARGS`; returns the exit status and the CSV lines of stdout.
int run_track(const TempDir& dir, const std::string& args, std::vector<std::string>& lines) {
  const auto out = dir / "stdout", err = dir / "stderr";
  const std::string cmd = "'" GEARPULSE_BINARY_DIR "/tools/gearpulse' track " + args + " >'" + out.string() +
                          "' 2>'" + err.string() + "'";
  const int raw = std::system(cmd.c_str());
  std::stringstream ss(read_text(out));
  lines.clear();
  for (std::string l; std::getline(ss, l);)
    lines.push_back(l);
  return WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
}

double cell(const std::string& text) {
  return text.empty() ? NAN : std::stod(text);
}

std::vector<Row> rows(const std::vector<std::string>& lines) {
  std::vector<Row> v;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    std::vector<std::string> cells;
    std::stringstream ss(lines[i]);
    for (std::string c; std::getline(ss, c, ',');)
      cells.push_back(c);
    if (lines[i].back() == ',') cells.emplace_back();
    REQUIRE(cells.size() == 4);
    v.push_back({cell(cells[0]), cell(cells[1]), cell(cells[2]), cell(cells[3])});
  }
  return v;
}

}  // namespace

TEST_CASE("track: --confidence adds a column and keeps low-confidence estimates") {
  TempDir dir;
  const sim::FrequencyTrajectory truth = [](double t) { return 90.0 + 3.0 * t; };
  sim::LighterSignalConfig g;
  g.sample_rate_hz = 8000.0;
  g.amplitude = 0.05;
  g.snr_db = -5.0;
  g.seed = 31;
  const auto x = sim::make_lighter_signal(g, truth, 8.0);
  std::string error;
  const std::string wav = (dir / "low.wav").string();
  REQUIRE(sim::write_wav_pcm16(wav, x, 1, 8000, error));

  std::vector<std::string> plain, rich;
  REQUIRE(run_track(dir, "'" + wav + "'", plain) == 0);
  REQUIRE(run_track(dir, "--confidence '" + wav + "'", rich) == 0);
  REQUIRE_FALSE(rich.empty());
  CHECK(plain.front() == "t,freq,snr_db");
  CHECK(rich.front() == "t,freq,snr_db,confidence");
  REQUIRE(rich.size() == plain.size());

  const auto v = rows(rich);
  std::size_t with_freq = 0, plain_freq = 0;
  for (std::size_t i = 0; i < v.size(); ++i) {
    CHECK(v[i].confidence >= 0.0);
    CHECK(v[i].confidence <= 1.0);
    with_freq += std::isfinite(v[i].freq);
    // The default output shows a frequency exactly where the hop is trusted.
    const std::string& line = plain[i + 1];
    const auto comma = line.find(',');
    const bool shown = comma + 1 < line.size() && line[comma + 1] != ',';
    plain_freq += shown;
    if (shown) CHECK(v[i].confidence >= 0.8);
  }
  CHECK(with_freq >= 0.9 * static_cast<double>(v.size()));
  CHECK(plain_freq < with_freq);
}

TEST_CASE(
    "track: --decision-lag keeps one row per hop, each estimate its own, and never lowers a confidence") {
  TempDir dir;
  // A launch through three gears at -5 dB: the windows after each shift decide the hops the filter doubted.
  const sim::FrequencyTrajectory truth = [](double t) {
    const double in_gear = std::fmod(t, 4.0);
    return 60.0 + 25.0 * in_gear - 8.0 * std::floor(t / 4.0);
  };
  sim::LighterSignalConfig g;
  g.sample_rate_hz = 8000.0;
  g.amplitude = 0.05;
  g.snr_db = -5.0;
  g.seed = 37;
  const auto x = sim::make_lighter_signal(g, truth, 12.0);
  std::string error;
  const std::string wav = (dir / "launch.wav").string();
  REQUIRE(sim::write_wav_pcm16(wav, x, 1, 8000, error));

  std::vector<std::string> at_once, later;
  REQUIRE(run_track(dir, "--confidence '" + wav + "'", at_once) == 0);
  REQUIRE(run_track(dir, "--confidence --decision-lag 0.5 '" + wav + "'", later) == 0);
  REQUIRE(later.size() == at_once.size());  // the held hops come out at the end of the file too
  const auto a = rows(at_once), b = rows(later);
  std::size_t raised = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(b[i].t == a[i].t);
    CHECK((b[i].freq == a[i].freq || (std::isnan(a[i].freq) && std::isnan(b[i].freq))));
    CHECK(b[i].confidence >= a[i].confidence - 1e-9);
    raised += b[i].confidence > a[i].confidence + 1e-9;
  }
  CHECK(raised > 0);
  std::vector<std::string> refused;
  CHECK(run_track(dir, "--decision-lag 3 '" + wav + "'", refused) != 0);
}
