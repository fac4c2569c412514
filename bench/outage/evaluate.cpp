// The outage bench's replay: each case's rows through the daemon's synthesis, the candidate IMM filter and
// the baselines with GPS blanked out by the outage protocol (bench/outage_protocol.hpp), scored per outage;
// with --worst, each bad outage's failure mode.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "bench/outage/outage.hpp"
#include "bench/outage_protocol.hpp"
#include "core/imm_speed_synth.hpp"
#include "core/speed_synth.hpp"

namespace gearpulse::bench::outage {

namespace {

constexpr double kMinDistance = 100.0;  // m: shorter outages have no meaningful relative distance error

// What the daemon's synthesis did at one row of an outage, for --worst.
struct Step {
  double speed = 0.0;
  int gear = 0;
};

// A gear of a model or a ladder within this log-ratio of a true gear's theta is that gear (neighbouring
// gears of the simulated ladders lie further apart).
constexpr double kSameGear = 0.04;

// The model's gear (index + 1) whose theta lies within `tolerance` of `theta` in ratio, 0 if none.
int gear_near(const GearModel& m, double theta, double tolerance) {
  int best = 0;
  double err = tolerance;
  for (std::size_t i = 0; i < m.gears.size(); ++i) {
    const double e = std::abs(std::log(m.gears[i].theta / theta));
    if (e < err) best = static_cast<int>(i) + 1, err = e;
  }
  return best;
}

// The failure mode of one outage (rows [begin, end) of a drive, `steps` the synthesis' output per row):
// the moment the error sets in (the first row from which the output stays more than 15 % and 1.5 m/s off
// the truth for 3 s, most rows of it) and what the car did around it. Returns {mode, detail}.
std::pair<std::string, std::string> outage_cause(const std::vector<Row>& rows, const std::vector<Step>& steps,
                                                 std::size_t begin, std::size_t end, const GearModel& model,
                                                 const std::vector<double>& true_theta) {
  constexpr double kHold = 3.0;  // s the error must last
  const auto off = [&](std::size_t i) {
    const double e = std::abs(steps[i].speed - rows[i].truth);
    return e > std::max(1.5, 0.15 * rows[i].truth);
  };
  std::size_t onset = end;
  for (std::size_t i = begin; i < end && onset == end; ++i) {
    if (!off(i)) continue;
    std::size_t n = 0, bad = 0, j = i;
    for (; j < end && rows[j].t - rows[i].t < kHold; ++j, ++n)
      bad += off(j) ? 1 : 0;
    if (bad >= 0.8 * static_cast<double>(n) && (j < end || n > 0)) onset = i;
  }
  const double t0 = rows[begin].t;
  if (onset == end) return {"no lasting error (many small ones)", ""};
  const double t_on = rows[onset].t;
  const bool sim = rows[begin].gear >= 0;
  char detail[160];
  std::snprintf(detail, sizeof detail, "%sfrom +%.1f s: out %.1f (g%d) truth %.1f km/h (g%d)",
                t_on - t0 < kHold ? "at outage start, " : "", t_on - t0, steps[onset].speed * kMsToKmh,
                steps[onset].gear, rows[onset].truth * kMsToKmh, rows[onset].gear);
  // The window around the onset: 5 s before it (reaching back before the outage) to 1 s after.
  std::size_t w0 = onset;
  while (w0 > 0 && rows[w0 - 1].t >= t_on - 5.0)
    --w0;
  std::size_t w1 = onset;
  while (w1 + 1 < rows.size() && rows[w1 + 1].t <= t_on + 1.0)
    ++w1;
  double min_truth = rows[onset].truth, declutched = 0.0;
  int jumps = 0, skip = 0;
  for (std::size_t i = w0; i <= w1; ++i) {
    min_truth = std::min(min_truth, rows[i].truth);
    const double dt = i + 1 < rows.size() ? std::min(rows[i + 1].t - rows[i].t, 5.0) : 0.0;
    if (rows[i].gear == 0 && rows[i].truth > 1.0) declutched += dt;
  }
  // Gears engaged through the window (clutch-out rows skipped): shifts and skips.
  int last_gear = 0;
  for (std::size_t i = w0; i <= w1; ++i) {
    if (rows[i].gear <= 0) continue;
    if (last_gear > 0 && rows[i].gear != last_gear) {
      ++jumps;
      if (std::abs(rows[i].gear - last_gear) >= 2) ++skip;
    }
    last_gear = rows[i].gear;
  }
  bool launched = false;  // the car stood within 10 s before the onset and moves at it
  for (std::size_t i = onset; i > 0 && rows[i].t >= t_on - 10.0; --i)
    if (rows[i].truth < 0.3 && rows[onset].truth > 1.0) launched = true;
  // Braking: from 3 s before the onset to 2 s after it the truth lost more than 2 m/s, or it stands in the
  // window.
  double fastest = 0.0;
  bool braking = min_truth < 0.3 && !launched;
  for (std::size_t i = onset; i > 0 && rows[i].t >= t_on - 3.0; --i)
    fastest = std::max(fastest, rows[i].truth);
  for (std::size_t i = onset; i < rows.size() && rows[i].t <= t_on + 2.0; ++i)
    braking = braking || rows[i].truth < fastest - 2.0;
  const bool too_fast = steps[onset].speed > rows[onset].truth;
  const int g_out = steps[onset].gear;
  if (sim) {
    // The fit: the true gear at the onset (or the last engaged) has no gear of the model, or the output's
    // gear is none of the car's.
    int g_true = rows[onset].gear;
    for (std::size_t i = onset; g_true <= 0 && i > w0; --i)
      g_true = rows[i - 1].gear;
    const int g_model = g_true > 0 && static_cast<std::size_t>(g_true) <= true_theta.size()
                            ? gear_near(model, true_theta[static_cast<std::size_t>(g_true - 1)], kSameGear)
                            : -1;
    if (g_model == 0) return {"fit lacks the engaged gear", detail};
    if (g_out > 0) {
      bool real_gear = false;
      for (const double th : true_theta)
        real_gear =
            real_gear ||
            std::abs(std::log(model.gears[static_cast<std::size_t>(g_out - 1)].theta / th)) < kSameGear;
      if (!real_gear) return {"fit invented the output's gear", detail};
    }
    if (braking && too_fast && g_out == 0) return {"braking declutched: deceleration lost", detail};
    if (launched) return {"launch", detail};
    if (braking) return {"braking: other", detail};
    const int g_now = rows[onset].gear > 0 ? g_model : 0;  // the model's gear engaged at the onset, 0: none
    if (g_out > 0 && g_now > 0 && g_out != g_now) {
      if (skip > 0) return {"wrong gear after a skip shift", detail};
      if (jumps > 0) return {"wrong gear after a shift", detail};
      return {"wrong gear, steady driving", detail};
    }
    if (g_out == 0 && g_now > 0) return {"in gear, read as declutched", detail};
    if (declutched >= 1.5 || g_now == 0) return {"declutched: speed drifted", detail};
    return {"other", detail};
  }
  if (braking && too_fast) return {"braking (real log)", detail};
  if (launched) return {"launch (real log)", detail};
  return {"moving (real log)", detail};
}

// --calibration: the belief of the daemon's synthesis at one outage sample against the truth (Calibration).
void calibrate(const gearpulse::SpeedSynthesizer& synth, const Row& r, double out_speed,
               const std::vector<double>& true_theta, Calibration& c) {
  const int gears = synth.ladder_gears();
  if (gears <= 0) return;
  const double tol = std::max(0.5, kCalibrationTolerance * r.truth);
  // The truth's position on the ladder: 0 declutched (or moving off), a gear, -1 a gear the ladder lacks.
  int truth = -1;
  if (r.gear == 0) truth = 0;
  if (r.gear > 0 && static_cast<std::size_t>(r.gear) <= true_theta.size()) {
    const double theta = true_theta[static_cast<std::size_t>(r.gear - 1)];
    for (int m = 1; m <= gears; ++m)
      if (std::abs(std::log(synth.ladder_theta(m) / theta)) < kSameGear) truth = m;
  }
  const bool labelled = r.gear >= 0 && truth >= 0;
  int lead = 0;
  for (int m = 1; m <= gears + 1; ++m)
    if (synth.position_probability(m) > synth.position_probability(lead)) lead = m;
  const double v_lead = std::max(synth.mode_track(lead).speed, 0.0);
  const double tol_lead = std::max(0.5, kCalibrationTolerance * v_lead);
  c.truth_below += r.truth < v_lead - tol_lead ? 1.0 : 0.0;
  c.truth_above += r.truth > v_lead + tol_lead ? 1.0 : 0.0;
  double mean = 0.0, p_true = 0.0;
  std::array<double, 2> no_gear{};  // the belief in declutched + moving off, its weighted speed
  for (int m = 0; m <= gears + 1; ++m) {
    const double p = synth.position_probability(m), v = std::max(synth.mode_track(m).speed, 0.0);
    mean += p * v;
    if (v < r.truth - tol) c.slower += p;
    if (v > r.truth + tol) c.faster += p;
    if (v < v_lead - tol_lead) c.below_lead += p;
    if (v > v_lead + tol_lead) c.above_lead += p;
    const bool gear = m >= 1 && m <= gears;
    if (!gear) no_gear[0] += p, no_gear[1] += p * v;
    if (!labelled || !gear) continue;
    const auto b = std::min<std::size_t>(static_cast<std::size_t>(p * 10.0), 9);
    c.p[b] += p, c.count[b] += 1.0, c.hits[b] += m == truth ? 1.0 : 0.0;
    if (m == truth) p_true = p, c.true_bias += v - r.truth;
    c.brier += (p - (m == truth ? 1.0 : 0.0)) * (p - (m == truth ? 1.0 : 0.0));
    if (truth > 0 && m < truth) c.slower_gear += p;
    if (truth > 0 && m > truth) c.faster_gear += p;
    if (truth == 0) c.gear_held += p;
  }
  if (labelled) {
    const auto b = std::min<std::size_t>(static_cast<std::size_t>(no_gear[0] * 10.0), 9);
    c.p[b] += no_gear[0], c.count[b] += 1.0, c.hits[b] += truth == 0 ? 1.0 : 0.0;
    if (truth == 0)
      p_true = no_gear[0], c.true_bias += no_gear[0] > 0.0 ? no_gear[1] / no_gear[0] - r.truth : 0.0;
    c.brier += (no_gear[0] - (truth == 0 ? 1.0 : 0.0)) * (no_gear[0] - (truth == 0 ? 1.0 : 0.0));
    c.log_score -= std::log(std::max(p_true, 1e-3));
    c.labelled += 1.0, c.true_mode += p_true;
    (truth > 0 ? c.in_gear : c.declutched) += 1.0;
    if (truth > 0) {
      c.no_gear += no_gear[0];
      const bool gear_lead = lead >= 1 && lead <= gears;
      c.lead_slower += gear_lead && lead < truth ? 1.0 : 0.0;
      c.lead_faster += gear_lead && lead > truth ? 1.0 : 0.0;
      c.lead_no_gear += gear_lead ? 0.0 : 1.0;
    }
  }
  c.samples += 1.0, c.bias += mean - r.truth, c.out_bias += out_speed - r.truth;
}

// Replays rows with outages; a row repeating an OBD logger's held rpm in an outage brings nothing (as
// `gearpulse replay` does).
// `where` names the case for --worst (line, car) and `true_theta` is the simulated car's ladder (empty for a
// real log). Rows from opt.debug_from to `debug_to` s are printed for --debug.
void replay(const std::vector<Row>& rows, const std::shared_ptr<const GearModel>& shared,
            const gearpulse::SynthTuning& tuning, bool live, const Options& opt, double debug_to,
            Results& res, const std::array<std::string, 2>& where, int style,
            const std::vector<double>& true_theta) {
  if (rows.empty()) return;
  const GearModel& model = *shared;
  gearpulse::SpeedSynthesizer synth(shared, tuning);
  gearpulse::ImmSpeedSynthesizer imm(shared);
  gearpulse::ImmLogReplayer imm_replayer(imm);
  const double t0 = rows.front().t;
  double last_gps = 0.0, last_freq = gearpulse::kMissing;
  int kept_gear = -1;
  double dist[kMethods + 1] = {};  // the methods', then the truth's
  double value[kMethods] = {};
  bool was_out = false, debug_head = false;
  gearpulse::SynthOutput o, o_imm;
  gearpulse::LogReplayer replayer(synth);
  std::vector<Step> steps(opt.worst > 0.0 ? rows.size() : 0);
  std::size_t out_begin = 0;  // first row of the current outage
  const auto close_outage = [&](std::size_t out_end) {
    if (dist[kMethods] >= kMinDistance) {
      for (int m = 0; m < kMethods; ++m)
        res.dist[m].push_back(100.0 * std::abs(dist[m] - dist[kMethods]) / dist[kMethods]);
      if (opt.worst > 0.0) {
        auto [cause, detail] = outage_cause(rows, steps, out_begin, out_end, model, true_theta);
        const double err = res.dist[0].back();
        res.cause.push_back(cause);
        if (err > opt.worst)
          res.worst.push_back({where[0], where[1], style, rows[out_begin].t - t0, err,
                               100.0 * (dist[0] - dist[kMethods]) / dist[kMethods], res.dist[2].back(),
                               res.dist[4].back(), std::move(cause), std::move(detail)});
      }
    }
    std::fill(std::begin(dist), std::end(dist), 0.0);
  };
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    const bool out = in_outage(r.t - t0);
    const double gps = out ? gearpulse::kMissing : r.gps;
    // Live, as the daemon steps at every hop; a log, as `gearpulse replay` does.
    o = live ? synth.step(r.t, gps, r.freq, r.gps_new) : replayer.step({r.t, gps, r.freq});
    if (opt.candidate)
      o_imm = live ? imm.step(r.t, gps, r.freq, r.gps_new) : imm_replayer.step({r.t, gps, r.freq});
    if (opt.debug_from < debug_to && r.t - t0 >= opt.debug_from && r.t - t0 <= debug_to) {
      const auto& flt = imm.filter();
      if (!debug_head) {
        debug_head = true;
        const auto& h = imm.habits();
        std::fprintf(stderr, "idle %.1f/%.2f bands:", h.idle, h.idle_sd);
        for (int g = 1; g <= static_cast<int>(model.gears.size()); ++g)
          std::fprintf(stderr, " %.1f/%.2f", std::exp(h.gear_revs_mean[static_cast<std::size_t>(g)]),
                       h.gear_revs_sd[static_cast<std::size_t>(g)]);
        std::fprintf(stderr, " sigma_freq %.2f synth ladder:", model.sigma_freq);
        for (int m = 1; m <= synth.ladder_gears(); ++m)
          std::fprintf(stderr, " %.4f", synth.ladder_theta(m));
        std::fprintf(stderr, "\n");
      }
      std::fprintf(stderr, "t %.1f %s truth %.1f g %d f %.1f | out %.1f p:", r.t - t0, out ? "OUT" : "gps",
                   r.truth, r.gear, r.freq, o_imm.speed);
      for (int m = 0; m < flt.modes(); ++m)
        std::fprintf(stderr, " %.2f(%.1f~%.1f)", flt.probability(m), flt.track(m).v,
                     std::sqrt(flt.track(m).pvv));
      // The daemon's synthesis: its output and its belief at each position of its ladder (0 = no gear,
      // then its gears, then moving off).
      std::fprintf(stderr, " || synth %.1f g%d p:", o.speed, o.gear);
      for (int m = 0; m <= synth.ladder_gears() + 1; ++m)
        std::fprintf(stderr, " %.2f", synth.position_probability(m));
      // ... and what it carries at each position of its ladder: speed m/s, acceleration ~ its sd m/s^2.
      for (int m = 0; m <= synth.ladder_gears() + 1; ++m) {
        const auto x = synth.mode_track(m);
        std::fprintf(stderr, " [%d %.1f %.2f~%.2f]", m, x.speed, x.accel, x.accel_sd);
      }
      std::fprintf(stderr, "\n");
    }
    if (std::isfinite(r.freq)) last_freq = r.freq;
    if (!steps.empty()) steps[i] = {o.speed, o.gear};
    if (!out) {
      if (was_out) close_outage(i);
      was_out = false;
      if (std::isfinite(gps)) {
        last_gps = gps;
        kept_gear = gps > 1.0 && std::isfinite(last_freq) ? nearest_gear(model, gps, last_freq) : -1;
      }
      continue;
    }
    if (!was_out) out_begin = i;
    was_out = true;
    const double f = last_freq;
    value[0] = o.speed;
    value[1] = o_imm.speed;
    value[2] = kept_gear >= 0 && std::isfinite(f) ? model.gears[static_cast<std::size_t>(kept_gear)].theta * f
                                                  : last_gps;
    value[3] = last_gps;
    value[4] = std::isfinite(f) && !model.gears.empty() ? hindsight_speed(model, r.truth, f) : last_gps;
    const double next_t = i + 1 < rows.size() ? rows[i + 1].t : r.t;
    const double dt = std::min(next_t - r.t, 5.0);
    for (int m = 0; m < kMethods; ++m) {
      dist[m] += value[m] * dt;
      res.speed[m].push_back(std::abs(value[m] - r.truth) * kMsToKmh);
    }
    dist[kMethods] += r.truth * dt;
    if (opt.calibration) calibrate(synth, r, o.speed, true_theta, res.calibration);
    if (opt.trace !=
        nullptr)  // t, truth, freq, then the candidate's gear, speed and belief, keep gear, hindsight
      std::fprintf(opt.trace, "%.1f,%.2f,%.2f,%d,%.2f,%.2f,%.2f,%.2f,%d,%.2f\n", r.t - t0, r.truth * kMsToKmh,
                   f, o_imm.gear, o_imm.speed * kMsToKmh, value[2] * kMsToKmh, value[4] * kMsToKmh,
                   imm.mode_probability(o_imm.gear), r.gear, o.speed * kMsToKmh);
  }
  if (was_out) close_outage(rows.size());
}

}  // namespace

Outcome evaluate(const Workload& w, const gearpulse::SynthTuning& tuning, const Options& opt) {
  Outcome o;
  o.all.resize(w.lines.size());
  o.styles.resize(w.lines.size());
  for (const Case& c : w.cases) {
    Results r;
    if (opt.trace != nullptr) std::fprintf(opt.trace, "# %s %d\n", c.car.c_str(), c.style);
    // A simulated case is named CAR/sSEED; --debug CAR takes every seed of the car.
    const std::string name = c.seed > 0 ? c.car + "/s" + std::to_string(c.seed) : c.car;
    const bool debugged = (c.car == opt.debug_car || name == opt.debug_car) && c.style == opt.debug_style;
    replay(c.rows, c.model, tuning, c.live, opt, debugged ? opt.debug_to : 0.0, r,
           {w.lines[c.line].label, name}, c.style, c.true_theta);
    o.styles[c.line][static_cast<std::size_t>(c.style)].append(r);
    o.all[c.line].append(r);
  }
  return o;
}

}  // namespace gearpulse::bench::outage
