#include <catch2/catch.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "tests/test_util.hpp"
#include "tools/sim/lighter_signal.hpp"

namespace sim = gearpulse::sim;

using gearpulse::test::TempDir;

namespace {

const std::string kTool = GEARPULSE_BINARY_DIR "/tools/gearpulse";

// A private temporary directory, removed with its contents.
std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

struct Result {
  int status = -1;
  std::string out, err;
  [[nodiscard]] std::vector<std::string> lines() const {
    std::vector<std::string> v;
    std::stringstream ss(out);
    for (std::string l; std::getline(ss, l);)
      v.push_back(l);
    return v;
  }
};

Result run(const TempDir& dir, const std::string& args) {
  const std::string out = (dir / "stdout").string(), err = (dir / "stderr").string();
  const std::string cmd = std::string("'") + kTool + "' track " + args + " >'" + out + "' 2>'" + err + "'";
  const int raw = std::system(cmd.c_str());
  Result r;
  r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  r.out = slurp(out);
  r.err = slurp(err);
  return r;
}

std::string make_wav(const TempDir& dir, const std::string& name, const std::vector<float>& x, int channels,
                     int rate) {
  std::string error;
  const std::string path = (dir / name).string();
  REQUIRE(sim::write_wav_pcm16(path, x, channels, rate, error));
  return path;
}

std::vector<float> engine(double fs, double seconds, const sim::FrequencyTrajectory& f, std::uint64_t seed,
                          double snr_db = 10.0) {
  sim::LighterSignalConfig g;
  g.sample_rate_hz = fs;
  g.amplitude = 0.05;
  g.snr_db = snr_db;
  g.seed = seed;
  return sim::make_lighter_signal(g, f, seconds);
}

struct Row {
  double t = 0.0;
  double freq = NAN;
  double snr = NAN;
};

std::vector<Row> rows(const Result& r) {
  std::vector<Row> v;
  const auto lines = r.lines();
  for (std::size_t i = 1; i < lines.size(); ++i) {
    Row row;
    const std::string& l = lines[i];
    const auto c1 = l.find(','), c2 = l.find(',', c1 + 1);
    REQUIRE(c1 != std::string::npos);
    REQUIRE(c2 != std::string::npos);
    row.t = std::stod(l.substr(0, c1));
    if (c2 > c1 + 1) row.freq = std::stod(l.substr(c1 + 1, c2 - c1 - 1));
    if (c2 + 1 < l.size()) row.snr = std::stod(l.substr(c2 + 1));
    v.push_back(row);
  }
  return v;
}

// Fraction of rows after `from` seconds whose freq is within `tol` Hz of the truth.
double hit_rate(const std::vector<Row>& v, const sim::FrequencyTrajectory& truth, double from, double tol) {
  std::size_t n = 0, hits = 0;
  for (const Row& r : v) {
    if (r.t < from) continue;
    ++n;
    hits += std::isfinite(r.freq) && std::abs(r.freq - truth(r.t)) <= tol;
  }
  return n ? static_cast<double>(hits) / static_cast<double>(n) : 0.0;
}

void check_one_line_error(const Result& r) {
  CHECK(r.status == 2);
  CHECK(r.out.find(',') == std::string::npos);  // no CSV rows
  REQUIRE_FALSE(r.err.empty());
  CHECK(r.err.find('\n') == r.err.size() - 1);
  CHECK(r.err.rfind("gearpulse: ", 0) == 0);
}

}  // namespace

TEST_CASE("track: prints t freq snr_db rows for a mono WAV") {
  TempDir dir;
  const sim::FrequencyTrajectory truth = [](double t) { return 100.0 + 8.0 * t; };
  const auto wav = make_wav(dir, "mono.wav", engine(8000.0, 3.0, truth, 1), 1, 8000);
  const Result r = run(dir, std::string("'") + wav + "'");
  REQUIRE(r.status == 0);
  const auto lines = r.lines();
  REQUIRE_FALSE(lines.empty());
  CHECK(lines[0] == "t,freq,snr_db");
  const auto v = rows(r);
  CHECK(v.size() >= 28);
  CHECK(v.size() <= 30);
  CHECK(v[0].t == Approx(0.1));
  CHECK(v[1].t - v[0].t == Approx(0.1));
  CHECK(hit_rate(v, truth, 0.5, 1.0) >= 0.9);
  CHECK(r.err.empty());
  // "-" is standard input, as libsndfile reads it.
  const Result piped = run(dir, "- <'" + wav + "'");
  REQUIRE(piped.status == 0);
  CHECK(piped.out == r.out);
}

TEST_CASE("track: stereo WAV takes the chosen channel or the mix") {
  TempDir dir;
  const sim::FrequencyTrajectory left = [](double) { return 90.0; };
  const sim::FrequencyTrajectory right = [](double) { return 150.0; };
  const auto a = engine(8000.0, 3.0, left, 2), b = engine(8000.0, 3.0, right, 3);
  std::vector<float> stereo(a.size() * 2);
  for (std::size_t i = 0; i < a.size(); ++i) {
    stereo[2 * i] = a[i];
    stereo[2 * i + 1] = b[i];
  }
  const auto wav = make_wav(dir, "stereo.wav", stereo, 2, 8000);
  const Result r0 = run(dir, "--channel 0 '" + wav + "'");
  REQUIRE(r0.status == 0);
  CHECK(hit_rate(rows(r0), left, 0.5, 1.0) >= 0.9);
  const Result r1 = run(dir, "--channel 1 '" + wav + "'");
  REQUIRE(r1.status == 0);
  CHECK(hit_rate(rows(r1), right, 0.5, 1.0) >= 0.9);
  const Result mix = run(dir, std::string("'") + wav + "'");
  REQUIRE(mix.status == 0);
  CHECK(rows(mix).size() >= 28);
  check_one_line_error(run(dir, "--channel 2 '" + wav + "'"));
  check_one_line_error(run(dir, "--channel -1 '" + wav + "'"));
}

TEST_CASE("track: hop window and band options are honoured") {
  TempDir dir;
  const sim::FrequencyTrajectory truth = [](double) { return 90.0; };
  const auto wav = make_wav(dir, "opt.wav", engine(44100.0, 3.0, truth, 4), 1, 44100);
  const Result fine = run(dir, "--hop 0.05 --window 0.2 '" + wav + "'");
  REQUIRE(fine.status == 0);
  const auto v = rows(fine);
  CHECK(v.size() >= 54);
  CHECK(v[1].t - v[0].t == Approx(0.05));
  CHECK(hit_rate(v, truth, 0.5, 0.5) >= 0.9);
  // The engine below a band of 120:200 Hz: its 2nd harmonic (180 Hz) must not be taken for it.
  const Result above = run(dir, "--band 120:200 '" + wav + "'");
  REQUIRE(above.status == 0);
  std::size_t tracked = 0;
  for (const Row& r : rows(above))
    tracked += std::isfinite(r.freq);
  CHECK(tracked <= 1);
}

TEST_CASE("track: silence and clipping give rows and no crash") {
  TempDir dir;
  const auto silent = make_wav(dir, "silent.wav", std::vector<float>(5100 * 2, 0.0f), 1, 5100);
  const Result r = run(dir, std::string("'") + silent + "'");
  REQUIRE(r.status == 0);
  const auto v = rows(r);
  CHECK(v.size() >= 18);
  for (const Row& row : v)
    CHECK(std::isnan(row.freq));
  // Clipped at full scale: 16-bit PCM saturates, the engine line is still there.
  const sim::FrequencyTrajectory truth = [](double) { return 120.0; };
  sim::LighterSignalConfig g;
  g.sample_rate_hz = 8000.0;
  g.amplitude = 3.0;
  g.snr_db = 20.0;
  g.seed = 5;
  const auto clipped = make_wav(dir, "clipped.wav", sim::make_lighter_signal(g, truth, 3.0), 1, 8000);
  const Result c = run(dir, std::string("'") + clipped + "'");
  REQUIRE(c.status == 0);
  CHECK(hit_rate(rows(c), truth, 0.5, 1.0) >= 0.9);
}

TEST_CASE("track: a WAV sampled barely above the band is tracked without reading past the spectrum") {
  // At 520 Hz the engine's 2nd and 3rd harmonics lie above Nyquist: they are left out of the fit.
  TempDir dir;
  const sim::FrequencyTrajectory truth = [](double) { return 80.0; };
  const auto wav = make_wav(dir, "slow.wav", engine(520.0, 3.0, truth, 3), 1, 520);
  const Result r = run(dir, std::string("'") + wav + "'");
  REQUIRE(r.status == 0);
  CHECK(rows(r).size() > 20);
}

TEST_CASE("track: bad input gives a one-line error and exit status 2") {
  TempDir dir;
  const sim::FrequencyTrajectory truth = [](double) { return 100.0; };
  const auto good = make_wav(dir, "good.wav", engine(8000.0, 2.0, truth, 6), 1, 8000);
  SECTION("missing file") {
    const Result r = run(dir, std::string("'") + (dir / "absent.wav").string() + "'");
    check_one_line_error(r);
    CHECK(r.err.find("absent.wav: cannot open: No such file or directory") != std::string::npos);
  }
  SECTION("empty file") {
    std::ofstream((dir / "empty.wav").string()).close();
    check_one_line_error(run(dir, std::string("'") + (dir / "empty.wav").string() + "'"));
  }
  SECTION("not audio at all") {
    std::ofstream((dir / "text.wav").string()) << "t,speed,freq\n1,2,3\n";
    const Result r = run(dir, std::string("'") + (dir / "text.wav").string() + "'");
    check_one_line_error(r);
    CHECK(r.err.find("(track reads a WAV recording; a CSV log of speed and rpm is for fit and replay)") !=
          std::string::npos);
    // The same on standard input: not a missing file named "-".
    const Result in = run(dir, "- <'" + (dir / "text.wav").string() + "'");
    check_one_line_error(in);
    CHECK(in.err.find("-: cannot read audio: ") != std::string::npos);
    CHECK(in.err.find("cannot open") == std::string::npos);
  }
  SECTION("truncated WAV") {
    const std::string bytes = slurp(good);
    std::ofstream((dir / "cut.wav").string(), std::ios::binary) << bytes.substr(0, bytes.size() / 3);
    const Result r = run(dir, std::string("'") + (dir / "cut.wav").string() + "'");
    check_one_line_error(r);
    CHECK(r.err.find("truncated") != std::string::npos);
  }
  SECTION("WAV of just one analysis window") {
    const auto wav = make_wav(dir, "short.wav", std::vector<float>(1280, 0.1f), 1, 8000);
    const Result r = run(dir, std::string("'") + wav + "'");
    check_one_line_error(r);
    // Exactly one window's length is too short; the message says why, not that it is shorter than one.
    CHECK(r.err.find("1280 frames (0.16 s)") != std::string::npos);
    CHECK(r.err.find("a little more than one window is needed") != std::string::npos);
  }
  SECTION("options the tracker refuses, alone or at the file's rate") {
    const auto wav = make_wav(dir, "tone.wav", std::vector<float>(16000, 0.1f), 1, 8000);
    Result r = run(dir, "--hop 0.005 --decision-lag 2 '" + wav + "'");
    check_one_line_error(r);
    CHECK(r.err.find("tracker options refused: decision lag 2 s is more than") != std::string::npos);
    CHECK(r.err.find("hops of 0.005 s") != std::string::npos);
    CHECK(r.err.find("tone.wav") == std::string::npos);  // the file is not to blame
    r = run(dir, "--band 30:3900 '" + wav + "'");
    check_one_line_error(r);
    CHECK(r.err.find("the tracker options do not suit") != std::string::npos);
    CHECK(r.err.find("tone.wav (8000 Hz): ") != std::string::npos);
  }
  SECTION("WAV with zero frames") {
    const auto wav = make_wav(dir, "zero.wav", {}, 1, 8000);
    check_one_line_error(run(dir, std::string("'") + wav + "'"));
  }
  SECTION("non-PCM WAV") {
    std::string bytes = slurp(good);
    bytes[20] = static_cast<char>(0x50);  // format tag 0x0050: MPEG, not PCM
    std::ofstream((dir / "mpeg.wav").string(), std::ios::binary) << bytes;
    check_one_line_error(run(dir, std::string("'") + (dir / "mpeg.wav").string() + "'"));
  }
  SECTION("rate too low for the band") {
    const auto wav = make_wav(dir, "low.wav", std::vector<float>(400 * 3, 0.1f), 1, 400);
    const Result r = run(dir, std::string("'") + wav + "'");
    check_one_line_error(r);
    CHECK(r.err.find("low.wav") != std::string::npos);
  }
  SECTION("band outside Nyquist") {
    const Result r = run(dir, "--band 50:4100 '" + good + "'");
    check_one_line_error(r);
    CHECK(r.err.find("Nyquist") != std::string::npos);
  }
  SECTION("bad options") {
    check_one_line_error(run(dir, "--band 50-200 '" + good + "'"));
    check_one_line_error(run(dir, "--band 50:x '" + good + "'"));
    check_one_line_error(run(dir, "--hop abc '" + good + "'"));
    check_one_line_error(run(dir, "--hop 0 '" + good + "'"));
    // As the daemon's configuration: a hop beyond 4 windows would skip the audio between them.
    const Result wide = run(dir, "--hop 0.7 '" + good + "'");
    check_one_line_error(wide);
    CHECK(wide.err.find("more than 4 windows") != std::string::npos);
    check_one_line_error(run(dir, "--window 0.01 '" + good + "'"));
    check_one_line_error(run(dir, "--bogus '" + good + "'"));
    check_one_line_error(run(dir, ""));
  }
}

TEST_CASE("track: one row per hop at hops far shorter than a read block") {
  TempDir dir;
  const sim::FrequencyTrajectory truth = [](double) { return 100.0; };
  const auto wav = make_wav(dir, "short-hops.wav", engine(8000.0, 3.0, truth, 7), 1, 8000);
  const Result r = run(dir, "--hop 0.001 '" + wav + "'");
  REQUIRE(r.status == 0);
  const auto v = rows(r);
  REQUIRE(v.size() > 2);
  // Windows of 0.16 s centred every millisecond: one row for every hop from the first to the last, none
  // missing (a read block holds more hops than the tracker's output queue).
  const double first = v.front().t, last = v.back().t;
  CHECK(first <= 0.09);  // the first whole window
  CHECK(last >= 2.9);
  CHECK(static_cast<double>(v.size()) == Approx((last - first) / 0.001 + 1.0).margin(1.0));
  for (std::size_t i = 1; i < v.size(); ++i)
    REQUIRE(v[i].t - v[i - 1].t < 0.0015);
}

TEST_CASE("track: a WAV whose header gives no length is read with a warning") {
  TempDir dir;
  const sim::FrequencyTrajectory truth = [](double) { return 100.0; };
  const auto good = make_wav(dir, "good.wav", engine(8000.0, 2.0, truth, 6), 1, 8000);
  const Result reference = run(dir, std::string("'") + good + "'");
  REQUIRE(reference.status == 0);
  std::string bytes = slurp(good);
  const auto data = bytes.find("data");
  REQUIRE(data != std::string::npos);
  // A recorder writing to a pipe, or cut off before it finished its header: the RIFF and data sizes are
  // placeholders for "unknown" (0xFFFFFFFF), not sizes the recording had.
  for (std::size_t i = 0; i < 4; ++i) {
    bytes[4 + i] = static_cast<char>(0xFF);
    bytes[data + 4 + i] = static_cast<char>(0xFF);
  }
  std::ofstream((dir / "streamed.wav").string(), std::ios::binary) << bytes;
  const Result r = run(dir, std::string("'") + (dir / "streamed.wav").string() + "'");
  CHECK(r.status == 0);
  CHECK(r.out == reference.out);
  CHECK(r.err.find("streamed.wav") != std::string::npos);
  CHECK(r.err.find("no length") != std::string::npos);

  // A recorder stopped before it went back to write the length: the sizes still 0, the audio after them.
  for (std::size_t i = 0; i < 4; ++i) {
    bytes[4 + i] = '\0';
    bytes[data + 4 + i] = '\0';
  }
  std::ofstream((dir / "unfinished.wav").string(), std::ios::binary) << bytes;
  const Result unfinished = run(dir, std::string("'") + (dir / "unfinished.wav").string() + "'");
  CHECK(unfinished.status == 0);
  CHECK(unfinished.out == reference.out);
  CHECK(unfinished.err.find("unfinished.wav") != std::string::npos);
  CHECK(unfinished.err.find("no length") != std::string::npos);
  // The header alone, sizes 0: no audio, as before.
  std::ofstream((dir / "empty.wav").string(), std::ios::binary) << bytes.substr(0, data + 8);
  const Result empty = run(dir, std::string("'") + (dir / "empty.wav").string() + "'");
  CHECK(empty.status == 2);
  CHECK(empty.err.find("no audio frames") != std::string::npos);
}
