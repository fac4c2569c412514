// The outage bench's output: a table line per line of the workload (per style for simulated cadences) with
// its figures, and --worst's list of bad outages with their failure modes.
#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "bench/outage/outage.hpp"
#include "bench/outage_protocol.hpp"

namespace gearpulse::bench::outage {

namespace {

constexpr const char* kMethodNames[kMethods] = {"gearpulse", "IMM cand.", "keep gear", "hold speed",
                                                "hindsight"};
constexpr const char* kStyleNames[4] = {"mixed", "urban", "jam", "highway"};

void print_header() {
  std::printf("%-34s %5s |", "", "outs");
  for (const char* n : kMethodNames)
    std::printf(" %-13s", n);
  std::printf("| speed km/h:");
  for (const char* n : kMethodNames)
    std::printf(" %-12s", n);
  std::printf("\n%-34s %5s |", "", "");
  for (int m = 0; m < kMethods; ++m)
    std::printf(" %-13s", "dist% med/p95");
  std::printf("|            ");
  for (int m = 0; m < kMethods; ++m)
    std::printf(" %-12s", "med/p95");
  std::printf("\n");
}

// Reports the daemon's synthesis' figures of a set as NAME_dist_med_pct, NAME_dist_p95_pct and their
// differences from keeping the gear (NAME_dist_med_minus_keep, NAME_dist_p95_minus_keep: below 0 is better).
void report(const std::string& name, const Results& r, Requirements& required) {
  const double med = quantile(r.dist[0], 0.5), p95 = quantile(r.dist[0], 0.95);
  required.report(name + "_dist_med_pct", med);
  required.report(name + "_dist_p95_pct", p95);
  required.report(name + "_dist_med_minus_keep", med - quantile(r.dist[2], 0.5));
  required.report(name + "_dist_p95_minus_keep", p95 - quantile(r.dist[2], 0.95));
}

void print_line(const std::string& label, const Results& r) {
  std::printf("%-34s %5zu |", label.c_str(), r.dist[0].size());
  for (int m = 0; m < kMethods; ++m)
    std::printf(" %5.2f/%6.2f ", quantile(r.dist[m], 0.5), quantile(r.dist[m], 0.95));
  std::printf("|            ");
  for (int m = 0; m < kMethods; ++m)
    std::printf(" %5.2f/%5.2f ", quantile(r.speed[m], 0.5), quantile(r.speed[m], 0.95));
  std::printf("\n");
  std::fflush(stdout);
}

}  // namespace

void print_outcome(const Workload& w, const Outcome& o, Requirements& required) {
  for (std::size_t l = 0; l < w.lines.size(); ++l) {
    const Line& line = w.lines[l];
    if (!line.title.empty()) {
      std::printf("\n%s\n", line.title.c_str());
      print_header();
    }
    if (line.styles) {
      for (std::size_t s = 0; s < 4; ++s)
        print_line(line.label + ", " + kStyleNames[s], o.styles[l][s]);
      print_line(line.label + ", ALL", o.all[l]);
    } else {
      print_line(line.label, o.all[l]);
    }
    report(line.key, o.all[l], required);
  }
}

// --worst: every outage of the daemon's synthesis beyond `worst` %, worst first, with its failure mode;
// then per line, per failure mode: its outages, those beyond `worst` and beyond the line's p95, and the p95
// the line would have were that mode's outages as good as the hindsight gear.
void print_worst(const Workload& w, const Outcome& o, double worst) {
  for (std::size_t l = 0; l < w.lines.size(); ++l) {
    const Results& r = o.all[l];
    if (r.cause.size() != r.dist[0].size() || r.dist[0].empty()) continue;
    std::vector<WorstOutage> beyond_worst = r.worst;
    std::sort(beyond_worst.begin(), beyond_worst.end(),
              [](const auto& a, const auto& b) { return a.err > b.err; });
    const double p95 = quantile(r.dist[0], 0.95);
    std::printf("\n%s: %zu outages, p95 %.2f %%, %zu beyond %g %% (error, keep gear, hindsight %%)\n",
                w.lines[l].label.c_str(), r.dist[0].size(), p95, beyond_worst.size(), worst);
    for (const WorstOutage& x : beyond_worst)
      std::printf("  %+7.1f %6.1f %5.1f  %-16s %-8s t %6.0f  %-36s %s\n", x.signed_err, x.keep, x.hindsight,
                  x.car.c_str(), kStyleNames[x.style], x.start, x.cause.c_str(), x.detail.c_str());
    std::vector<std::string> causes = r.cause;
    std::sort(causes.begin(), causes.end());
    causes.erase(std::unique(causes.begin(), causes.end()), causes.end());
    // The error beyond the target (5 %), summed over the outages: each mode's share of it.
    constexpr double kTarget = 5.0;
    double excess = 0.0;
    for (const double e : r.dist[0])
      excess += std::max(e - kTarget, 0.0);
    std::printf("  %-44s %5s %6s %5s %13s %13s\n", "failure mode", "outs", ">worst", ">p95", "% err > 5 %",
                "p95 if fixed");
    for (const std::string& c : causes) {
      int n = 0, beyond = 0, above = 0;
      double mine = 0.0;
      std::vector<double> fixed = r.dist[0];
      for (std::size_t k = 0; k < r.cause.size(); ++k) {
        if (r.cause[k] != c) continue;
        ++n;
        beyond += r.dist[0][k] > worst ? 1 : 0;
        above += r.dist[0][k] > p95 ? 1 : 0;
        mine += std::max(r.dist[0][k] - kTarget, 0.0);
        fixed[k] = r.dist[4][k];
      }
      std::printf("  %-44s %5d %6d %5d %13.1f %13.2f\n", c.c_str(), n, beyond, above,
                  excess > 0.0 ? 100.0 * mine / excess : 0.0, quantile(fixed, 0.95));
    }
  }
}

// --calibration: per line, the reliability of the daemon's synthesis' belief (each mode's probability by
// tenths against how often that mode is the truth) and where its wrong belief lies, slower or faster.
void print_calibration(const Workload& w, const Outcome& o) {
  for (std::size_t l = 0; l < w.lines.size(); ++l) {
    const Calibration& c = o.all[l].calibration;
    if (!(c.samples > 0.0)) continue;
    const double n = c.samples, k = std::max(c.labelled, 1.0);
    std::printf(
        "\n%s: %.0f samples; belief slower %.3f faster %.3f than the truth; mean speed %+.2f km/h,"
        " output %+.2f km/h\n",
        w.lines[l].label.c_str(), n, c.slower / n, c.faster / n, c.bias / n * kMsToKmh,
        c.out_bias / n * kMsToKmh);
    std::printf(
        "  below the most probable mode's speed: belief %.3f, truth %.3f; above: belief %.3f, truth %.3f\n",
        c.below_lead / n, c.truth_below / n, c.above_lead / n, c.truth_above / n);
    if (!(c.labelled > 0.0)) continue;
    std::printf(
        "  true mode: belief %.3f, its speed %+.2f km/h; in gear (%.0f): slower gears %.3f, faster"
        " %.3f, no gear %.3f; declutched (%.0f): gears %.3f",
        c.true_mode / k, c.true_bias / k * kMsToKmh, c.in_gear, c.slower_gear / std::max(c.in_gear, 1.0),
        c.faster_gear / std::max(c.in_gear, 1.0), c.no_gear / std::max(c.in_gear, 1.0), c.declutched,
        c.gear_held / std::max(c.declutched, 1.0));
    const double g = std::max(c.in_gear, 1.0);
    std::printf(
        "\n  in gear, the most probable mode: a slower gear %.3f, a faster gear %.3f, no gear %.3f\n  "
        "Brier %.4f, log score %.4f nats\n  reliability (p: mean p / right / n):",
        c.lead_slower / g, c.lead_faster / g, c.lead_no_gear / g, c.brier / k, c.log_score / k);
    for (std::size_t b = 0; b < c.p.size(); ++b)
      if (c.count[b] > 0.0)
        std::printf(" %.2f/%.2f/%.0f", c.p[b] / c.count[b], c.hits[b] / c.count[b], c.count[b]);
    std::printf("\n");
  }
}

}  // namespace gearpulse::bench::outage
