// `gearpulse fit`: learns the gear scales from sample logs and prints the model as JSON (docs/interfaces.md).
#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>

#include "common/atomic_file.hpp"
#include "core/estimator.hpp"
#include "core/gear_model.hpp"
#include "drivers/thread_slice_runner.hpp"
#include "tools/gearpulse/commands.hpp"
#include "tools/gearpulse/fit_plot.hpp"
#include "tools/gearpulse/fit_summary.hpp"
#include "tools/gearpulse/sample_files.hpp"

namespace gearpulse::cli {
namespace {

constexpr int kMaxGears = static_cast<int>(GearModel::kMaxGears);

struct FitCommand {
  std::string gears = "auto";
  std::optional<std::string> ratios;  // unset: no priors (an empty --ratios is an error, not "none")
  std::string out;
  std::string plot;
  std::string speed = "auto";
  std::optional<double> row_seconds;      // --row-seconds, unset when not given (the reader's default)
  std::optional<std::string> speed_unit;  // --speed-unit, unset when not given
  std::vector<std::string> files;
};

int parse_gears(const std::string& text) {
  if (text == "auto") return 0;
  int n = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), n);
  if (ec != std::errc() || ptr != text.data() + text.size() || n < 2 || n > kMaxGears)
    throw UsageError("--gears must be 'auto' or a gear count from 2 to " + std::to_string(kMaxGears) +
                     ", not '" + text + "'");
  return n;
}

std::vector<double> parse_ratios(const std::optional<std::string>& given) {
  std::vector<double> ratios;
  if (!given) return ratios;
  const std::string& text = *given;
  std::size_t start = 0;
  while (start <= text.size()) {
    std::size_t comma = text.find(',', start);
    if (comma == std::string::npos) comma = text.size();
    const std::string item = text.substr(start, comma - start);
    double c = 0.0;
    const auto [ptr, ec] = std::from_chars(item.data(), item.data() + item.size(), c);
    if (item.empty() || ec != std::errc() || ptr != item.data() + item.size() || !std::isfinite(c) ||
        c <= 1.0)
      throw UsageError(
          "--ratios must be numbers above 1 separated by commas (as the paper's Table 2), not '" + text +
          "'");
    ratios.push_back(c);
    start = comma + 1;
  }
  if (ratios.size() + 1 > static_cast<std::size_t>(kMaxGears)) throw UsageError("--ratios: too many gears");
  return ratios;
}

// Writes `text` to `path` whole or not at all, and on disk before it returns (a car PC loses power without
// warning): a temporary file synced and renamed over it, keeping an existing file's permissions. A
// symbolic link is followed, so the file it points to is replaced and the link stays; a path that is there
// but is no regular file (a FIFO, /dev/stdout, a device) is written to directly, not replaced by a file.
// Whether it is one is asked of the kernel, which resolves /dev/stdout's link into /proc: the target that
// link names for a pipe ("pipe:[N]") is no path.
void write_file_atomically(const std::string& path, const std::string& text) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (const fs::file_status st = fs::status(path, ec); !ec && fs::exists(st) && !fs::is_regular_file(st)) {
    if (fs::is_directory(st)) throw UsageError(path + ": is a directory");
    std::ofstream out(path, std::ios::binary);
    if (!out) throw UsageError(path + ": cannot write: " + std::strerror(errno));
    out << text;
    out.flush();
    if (!out) throw UsageError(path + ": write failed");
    return;
  }
  fs::path target = path;
  for (int hops = 0; fs::is_symlink(target, ec) && hops < 40; ++hops) {
    const fs::path link = fs::read_symlink(target, ec);
    if (ec) break;
    target = link.is_absolute() ? link : target.parent_path() / link;
  }
  try {
    gearpulse::write_file_atomic(target, text);
  } catch (const gearpulse::DirectorySyncError& e) {
    // In place, but a power cut may still bring back what was there before.
    std::fprintf(stderr, "gearpulse: warning: %s: written, but its directory could not be synced: %s\n",
                 path.c_str(), e.code().message().c_str());
  } catch (const std::system_error& e) {
    throw UsageError(path + ": cannot write: " + e.code().message());
  }
}

// A gear count forced above the car's splits a gear in two: neighbours whose thetas are not told apart by
// their standard errors (or lie within 1 %) are named, so the user does not take them for two gears.
void warn_indistinct_gears(const GearModel& model, const std::string& gears) {
  constexpr double kMinGap = 0.01;  // relative
  constexpr double kStderrs = 3.0;
  for (std::size_t i = 1; i < model.gears.size(); ++i) {
    const Gear& a = model.gears[i - 1];
    const Gear& b = model.gears[i];
    const double gap = std::log(b.theta / a.theta);
    const double se = std::hypot(a.std_error / a.theta, b.std_error / b.theta);
    if (gap < std::max(kMinGap, kStderrs * se))
      std::fprintf(stderr,
                   "gearpulse: warning: gears %zu and %zu are one (theta %.5f and %.5f): the data has fewer "
                   "gears than %s\n",
                   i, i + 1, a.theta, b.theta, gears.c_str());
  }
}

// --out or --plot naming one of the logs (`fit --out drive1.csv drive2.csv`, a slip of the shell's
// completion) would replace a drive with the model: refused before anything is read. Regular files only: a
// terminal or a device written into (/dev/stdout) replaces nothing.
void check_outputs_spare_logs(const FitCommand& cmd) {
  for (const auto& [option, path] : {std::pair{"--out", cmd.out}, std::pair{"--plot", cmd.plot}}) {
    std::error_code regular_ec;
    if (path.empty() || !std::filesystem::is_regular_file(path, regular_ec)) continue;
    for (const std::string& file : cmd.files) {
      std::error_code ec;
      if (std::filesystem::equivalent(path, file, ec) && !ec)
        throw UsageError(std::string(option) + " " + path + " is one of the logs given (" + file +
                         "): it would be replaced; name another file");
    }
  }
  // --out and --plot naming one file: the plot would replace the model. A file that exists is compared as
  // the file it is (a link, another spelling), one that does not yet by its absolute, normal path.
  if (cmd.out.empty() || cmd.plot.empty()) return;
  namespace fs = std::filesystem;
  std::error_code ec;
  const bool same =
      fs::exists(cmd.out, ec) && fs::exists(cmd.plot, ec)
          ? fs::is_regular_file(cmd.out, ec) && fs::equivalent(cmd.out, cmd.plot, ec) && !ec
          : fs::absolute(cmd.out, ec).lexically_normal() == fs::absolute(cmd.plot, ec).lexically_normal();
  if (same)
    throw UsageError("--out " + cmd.out + " and --plot " + cmd.plot +
                     " name the same file: the plot would replace the model; name two files");
}

int run_fit(const FitCommand& cmd) {
  check_outputs_spare_logs(cmd);
  ThreadSliceRunner threads;  // a large log's passes in two threads, one per half
  FitOptions options;
  options.parallel = &threads;
  options.gears = parse_gears(cmd.gears);
  options.ratios = parse_ratios(cmd.ratios);
  if (!options.ratios.empty() && options.gears != 0 &&
      options.gears != static_cast<int>(options.ratios.size()) + 1)
    throw UsageError("--gears " + cmd.gears + " does not match --ratios (" +
                     std::to_string(options.ratios.size()) + " ratios mean " +
                     std::to_string(options.ratios.size() + 1) + " gears)");
  ReadOptions read;
  read.torque_speed = parse_torque_speed(cmd.speed);
  if (cmd.row_seconds) read.row_seconds = *cmd.row_seconds;
  if (cmd.speed_unit) read.speed_unit = speed_unit_named(*cmd.speed_unit);

  const std::vector<SampleLog> logs = read_sample_files(cmd.files, read);
  warn_row_seconds(logs, cmd.row_seconds.has_value(), false);
  std::vector<Sample> samples;
  for (const SampleLog& log : logs)
    samples.insert(samples.end(), log.samples.begin(), log.samples.end());
  std::size_t moving = 0;
  for (const Sample& s : samples)
    moving += s.has_speed() && s.has_freq() && s.speed > 0.0 && s.freq > 0.0;
  if (moving == 0) {
    const std::string what = cmd.files.size() == 1 ? cmd.files.front() : "the input files";
    throw UsageError(what +
                     ": nothing to fit: no sample has both a speed above zero and an engine frequency");
  }

  // Torque exports that read the speed from GPS and from the car: the ladder from the wheel speed, scaled
  // to GPS (core/estimator.hpp says why).
  const std::vector<SampleLog> wheel =
      read.torque_speed == TorqueSpeed::kAuto ? read_wheel_speeds(cmd.files, logs) : std::vector<SampleLog>{};
  FitResult result;
  try {
    if (wheel.empty()) {
      result = fit_gear_model(samples, options);
    } else {
      std::vector<TwoSpeedLog> both;
      for (std::size_t i = 0; i < logs.size(); ++i)
        both.push_back({logs[i].samples, wheel[i].samples});
      result = fit_gear_model_two_speeds(both, options);
    }
  } catch (const std::invalid_argument& e) {
    throw UsageError(e.what());
  }
  if (const auto scale = result.model.extra.find("speed_scale"); scale != result.model.extra.end()) {
    // The plot shows what the ladder was read from, on the GPS scale.
    const double slope = scale->value("slope", 1.0), offset = scale->value("offset", 0.0);
    samples.clear();
    for (const SampleLog& log : wheel)
      for (Sample x : log.samples) {
        if (x.has_speed() && x.speed > 0.0) x.speed = std::max(slope * x.speed + offset, 0.0);
        samples.push_back(x);
      }
    std::fprintf(stderr,
                 "gearpulse: gears read from the OBD wheel speed (no GPS lag), mapped onto GPS speed as "
                 "%.4f x + %.3f m/s (%zu instants); --speed gps fits the GPS speed alone\n",
                 slope, offset, scale->value("pairs", std::size_t{0}));
  }
  const std::string json = serialize_model(result.model);
  // Files first: a path that cannot be written is an error before anything is printed.
  if (!cmd.out.empty()) write_file_atomically(cmd.out, json);
  if (!cmd.plot.empty()) write_file_atomically(cmd.plot, ratio_histogram_svg(samples, result.model));
  std::fwrite(json.data(), 1, json.size(), stdout);
  std::fflush(stdout);
  if (result.model.gears.empty()) {
    const std::string reason =
        result.model.reason.empty() ? "no discrete gear ladder in the data" : result.model.reason;
    // An automatic's log ends here by design; a manual's thin log too, and its user can drive more.
    std::fprintf(
        stderr,
        "gearpulse: no gear ladder: %s; an automatic or CVT has none (no speed from the engine in outages), "
        "a manual car's logs show one with more driving in each gear\n",
        reason.c_str());
  }
  // How good the model is, in the car's terms, and what to log when it is thin (stderr: stdout is the JSON).
  const bool rpm_logs = std::none_of(logs.begin(), logs.end(), [](const SampleLog& log) {
    return log.format == SampleFileFormat::kGeneric;
  });
  std::fputs(fit_summary(result.model, samples, rpm_logs).c_str(), stderr);
  // A count forced by --gears or by the ratios of --ratios (paper mode fits as many gears as the priors
  // say, a ladder or not: an automatic's log gives two gears 0.002 % apart).
  if (options.gears != 0) {
    warn_indistinct_gears(result.model, "--gears " + cmd.gears);
    if (const auto doubt = result.model.extra.find("forced_doubt"); doubt != result.model.extra.end())
      std::fprintf(stderr, "gearpulse: warning: the data does not show %s gears: %s\n", cmd.gears.c_str(),
                   doubt->value("reason", std::string()).c_str());
  } else if (!options.ratios.empty())
    warn_indistinct_gears(result.model, "--ratios gives (" + std::to_string(options.ratios.size() + 1) + ")");
  return 0;
}

}  // namespace

void add_fit(CLI::App& app, int& status) {
  auto cmd = std::make_shared<FitCommand>();
  CLI::App* sub =
      app.add_subcommand("fit", "Learn the gear scales (theta per gear) from sample logs; print JSON");
  // Checked as it is parsed, so that `--gears model.csv` names the bad count rather than a missing file.
  sub->add_option("--gears", cmd->gears, "Number of gears, or 'auto' to choose from the data")
      ->capture_default_str()
      ->check(CLI::Validator(
          [](std::string& text) {
            try {
              (void)parse_gears(text);
            } catch (const UsageError&) {
              return "must be 'auto' or a gear count from 2 to " + std::to_string(kMaxGears) + ", not '" +
                     text + "'";
            }
            return std::string();
          },
          "auto|N"));
  sub->add_option(
      "--ratios", cmd->ratios,
      "Prior ratios c1,... top gear down (paper's Table 2, e.g. 1.25,1.35,1.50,1.7): the paper's method");
  sub->add_option("--out", cmd->out, "Also write the model JSON to this file");
  sub->add_option("--plot", cmd->plot, "Write an SVG of the ratio histogram with the fitted gears");
  sub->add_option("--speed", cmd->speed,
                  "Torque Pro, named-column and PID-row logs: speed column to use, auto (GPS if any; a "
                  "Torque log with an OBD speed too has its gears read from the wheel speed mapped onto "
                  "GPS), gps or obd")
      ->capture_default_str();
  add_row_seconds_option(*sub, cmd->row_seconds);
  add_speed_unit_option(*sub, cmd->speed_unit);
  sub->add_option("files", cmd->files,
                  "Sample logs (CSV): t,speed,freq, Torque Pro, Carloop, speed,rpm, phone OBD apps' "
                  "(columns named rpm and speed with its unit or --speed-unit, or SECONDS,PID,VALUE rows); "
                  "man gearpulse")
      ->required();
  sub->callback([cmd, &status] { status = run_fit(*cmd); });
}

}  // namespace gearpulse::cli
