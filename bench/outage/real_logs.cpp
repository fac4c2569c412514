// The outage bench's real-log workload: a car's logs, fitted on some drives and replayed on the others.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "bench/outage/outage.hpp"
#include "bench/outage_protocol.hpp"
#include "core/estimator.hpp"
#include "core/sample_io.hpp"

namespace gearpulse::bench::outage {

namespace fs = std::filesystem;

namespace {

std::vector<std::vector<Sample>> read_logs(const fs::path& dir, const std::string& prefix) {
  std::vector<std::vector<Sample>> logs;
  for (const auto& p : csv_logs(dir, prefix)) {
    std::ifstream in(p, std::ios::binary);
    logs.push_back(gearpulse::read_samples(in, p.string()).samples);
  }
  return logs;
}

std::vector<Row> rows_of(const std::vector<Sample>& samples) {
  std::vector<Row> rows;
  for (const Sample& s : samples)
    if (s.has_speed()) rows.push_back({s.t, s.speed, s.freq, s.speed, true});
  return rows;
}

void fold(const std::vector<std::vector<Sample>>& train, const std::vector<std::vector<Sample>>& test,
          Workload& w) {
  std::vector<Sample> pooled;
  for (const auto& l : train)
    pooled.insert(pooled.end(), l.begin(), l.end());
  const auto model = std::make_shared<const GearModel>(gearpulse::fit_gear_model(pooled, {}).model);
  // Each replayed log is named KEY#N (N counts the line's logs), for --worst and --debug.
  for (const auto& l : test) {
    std::size_t n = 0;
    for (const Case& c : w.cases)
      n += c.line == w.lines.size() - 1 ? 1 : 0;
    w.cases.push_back({w.lines.size() - 1,
                       0,
                       w.lines.back().key + "#" + std::to_string(n),
                       rows_of(l),
                       model,
                       false,
                       {},
                       0});
  }
}

std::pair<std::vector<std::vector<Sample>>, std::vector<std::vector<Sample>>> halves(std::vector<Sample> all,
                                                                                     double row_s) {
  for (Sample& s : all)
    s.t *= row_s;
  const auto half = static_cast<long>(all.size() / 2);
  return {{{all.begin(), all.begin() + half}}, {{all.begin() + half, all.end()}}};
}

}  // namespace

// The tuning set's car (the Etios) or the report set's (Louisville, the Swift), never both in one run: the
// figures a design is chosen on are not printed beside those that report it.
void real_logs(const fs::path& root, bool report_set, Workload& w) {
  std::string title = std::string("Real logs, ") + (report_set ? "REPORT" : "TUNING") +
                      " set (fit on some drives of a car, replay its others)";
  const auto add_line = [&](const char* label, const char* key) {
    w.lines.push_back({title, label, key, false});
    title.clear();
  };
  if (!report_set) {
    const auto drives = read_logs(root / "carloop-etios", "drive");
    const auto longs = read_logs(root / "carloop-etios", "long");
    if (!drives.empty() && !longs.empty()) {
      add_line("TUNING Etios (OBD ~1.8 s)", "etios");
      fold(drives, longs, w);
      fold(longs, drives, w);
    }
    return;
  }
  const auto louis = read_logs(root / "torque-louisville", "");
  if (!louis.empty()) {
    const auto [a, b] = halves(louis.front(), 1.0);
    add_line("REPORT Louisville (1 Hz GPS)", "louisville");
    fold(a, b, w);
    fold(b, a, w);
  }
  const auto swift = read_logs(root / "swift-147", "");
  for (const double row_s : {1.0, 2.0}) {
    if (swift.empty()) break;
    const auto [a, b] = halves(swift.front(), row_s);
    if (row_s == 1.0)
      add_line("REPORT Swift (1 s per row)", "swift_1s");
    else
      add_line("REPORT Swift (2 s per row)", "swift_2s");
    fold(a, b, w);
    fold(b, a, w);
  }
}

// Logs a user gives (--log, repeatable): one car's drives. Two folds: the logs in even places against
// those in odd places, each fitted on one and replayed on the other; a single log is split in halves.
void given_logs(const std::vector<fs::path>& paths, double row_s, Workload& w) {
  gearpulse::ReadOptions options;
  options.row_seconds = row_s;
  std::vector<std::vector<Sample>> logs;
  for (const fs::path& p : paths) {
    std::ifstream in(p, std::ios::binary);
    if (!in) throw gearpulse::SampleFileError(p.string() + ": cannot open");
    gearpulse::SampleLog log = gearpulse::read_samples(in, p.string(), options);
    for (const std::string& warning : log.warnings)
      std::fprintf(stderr, "bench_outage: warning: %s\n", warning.c_str());
    if (log.skipped_count > 0)
      std::fprintf(stderr, "bench_outage: %s: skipped %zu bad rows (first: %s)\n", p.c_str(),
                   log.skipped_count, log.skipped.front().c_str());
    logs.push_back(std::move(log.samples));
  }
  w.lines.push_back({"Logs given (fit on some, replay the others)",
                     logs.size() == 1 ? "the log's halves" : "even against odd logs", "given", false});
  if (logs.size() == 1) {
    const auto [a, b] = halves(logs.front(), 1.0);
    fold(a, b, w);
    fold(b, a, w);
    return;
  }
  std::vector<std::vector<Sample>> even, odd;
  for (std::size_t i = 0; i < logs.size(); ++i)
    (i % 2 == 0 ? even : odd).push_back(std::move(logs[i]));
  fold(even, odd, w);
  fold(odd, even, w);
}

}  // namespace gearpulse::bench::outage
