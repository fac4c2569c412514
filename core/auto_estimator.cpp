// Auto mode, no priors: candidate gear scales from the modes of the density of log(v/s), EM fits of the
// generalised mixture for every gear count, the count chosen by BIC among ladders that pass physical
// checks, then a polish on the full data and standard errors from the observed information.
// This file holds the driver (fit_auto) and its EM and BIC; the candidates and the judge of a ladder's
// physics live in auto_candidates.cpp, the lag search in auto_lag_search.cpp, the completion of the chosen
// ladder in auto_ladder_completion.cpp.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>

#include "core/auto_estimator_internal.hpp"
#include "core/estimator.hpp"

namespace gearpulse::detail {
namespace {

constexpr int kMaxCandidates = 10;              // gear scales tried at first (more than any gearbox has)
constexpr std::size_t kWorkingSamples = 16000;  // model selection runs on a subsample of this size
constexpr int kFullDataIterations = 4;
constexpr std::size_t kClutchBins = 24;

// One sample from each of `target` equal strata of the data, spread over its time as a stride would be,
// at an offset within the stratum that steps by the golden ratio's fraction from one stratum to the next.
// A plain stride aliases with any period of the data that shares its factors (every 150th sample of a
// 2400-sample drive repeated 1000 times is one of the same 16 samples of the drive); the golden-ratio
// offsets cover every phase of any period evenly.
MixtureData subsample(const MixtureData& all, std::size_t target) {
  if (all.size() <= target) return all;
  MixtureData out;
  out.parallel = all.parallel;
  out.stop = all.stop;
  const double stride = static_cast<double>(all.size()) / static_cast<double>(target);
  const double golden = 0.5 * (std::sqrt(5.0) - 1.0);
  for (std::size_t i = 0; i < target; ++i) {
    const double offset = std::fmod(static_cast<double>(i) * golden, 1.0);
    const auto k =
        std::min(all.size() - 1, static_cast<std::size_t>((static_cast<double>(i) + offset) * stride));
    out.v.push_back(all.v[k]);
    out.s.push_back(all.s[k]);
  }
  return out;
}

MixtureParams without(const MixtureParams& p, int drop) {
  MixtureParams q = p;
  q.theta.erase(q.theta.begin() + drop);
  q.beta_clutch += q.alpha[static_cast<std::size_t>(drop)];
  q.alpha.erase(q.alpha.begin() + drop);
  return q;
}

}  // namespace

// Generalised EM until the log-likelihood gain per sample falls below tol. Returns the log-likelihood of
// the final parameters if final_value, else that of the last E-step (saves a pass on large data).
double run_em(const MixtureData& data, MixtureParams& p, int max_iter, double tol, bool final_value) {
  double previous = -INFINITY;
  double ll = -INFINITY;
  for (int it = 0; it < max_iter; ++it) {
    const EStepStats st = e_step(data, p);
    ll = st.log_likelihood;
    m_step(st, p, false, false);
    // Keep constraint (5): a component that crossed its neighbour is put back in order.
    std::vector<std::size_t> order(p.theta.size());
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(),
              [&](std::size_t a, std::size_t b) { return p.theta[a] < p.theta[b]; });
    std::vector<double> th;
    std::vector<double> al;
    for (std::size_t i : order) {
      th.push_back(p.theta[i]);
      al.push_back(p.alpha[i]);
    }
    p.theta = th;
    p.alpha = al;
    if (std::abs(ll - previous) < tol * static_cast<double>(data.size())) break;
    previous = ll;
  }
  return final_value ? log_likelihood(data, p) : ll;
}

MixtureParams initial_params(const MixtureData& data, const std::vector<double>& log_ratios, double vmax) {
  MixtureParams p;
  for (double r : log_ratios)
    p.theta.push_back(std::exp(r));
  std::sort(p.theta.begin(), p.theta.end());
  std::size_t standing = 0;
  for (double v : data.v)
    standing += v < 0.5 ? 1 : 0;
  const double stand_share =
      std::clamp(static_cast<double>(standing) / static_cast<double>(data.size()), 0.02, 0.9);
  p.beta_stand = stand_share;
  p.stand_sigma = 0.2;
  p.beta_clutch = 0.1;
  const double gear_share = std::max(1.0 - p.beta_stand - p.beta_clutch, 0.05);
  p.alpha.assign(p.theta.size(), gear_share / static_cast<double>(p.theta.size()));
  const double total = gear_share + p.beta_stand + p.beta_clutch;
  for (double& a : p.alpha)
    a /= total;
  p.beta_stand /= total;
  p.beta_clutch /= total;
  p.g_lo = 0.0;
  p.g_hi = vmax * 1.0001 + 1e-6;
  p.g_density.assign(kClutchBins, 1.0 / (p.g_hi - p.g_lo));
  std::vector<double> s_sorted = data.s;
  std::nth_element(s_sorted.begin(), s_sorted.begin() + static_cast<std::ptrdiff_t>(s_sorted.size() / 2),
                   s_sorted.end());
  p.sigma_s = 0.01 * s_sorted[s_sorted.size() / 2];
  p.sigma_v = 0.01 * vmax + 0.05;
  return p;
}

double bic_of(double log_likelihood, int gears, std::size_t n) {
  // Free parameters: theta and alpha per gear, two sigmas, standstill weight and width, clutch weight and
  // its bins; only the 2 per gear differ between candidates.
  const double n_params = 2.0 * gears + 2.0 + 2.0 + 1.0 + static_cast<double>(kClutchBins - 1);
  return -2.0 * log_likelihood + n_params * std::log(static_cast<double>(n));
}

GearModel fit_auto(const MixtureData& input, int gears, bool single_gear) {
  const Aligned aligned = aligned_channels(input);
  const MixtureData& all = aligned.data;
  GearModel model;
  model.method = "auto";
  model.extra["speed_lag"] = aligned.lag;
  model.samples = all.size();
  std::vector<double> log_ratios;
  double vmax = 0.0;
  for (std::size_t k = 0; k < all.size(); ++k) {
    vmax = std::max(vmax, all.v[k]);
    if (all.v[k] > kMovingSpeed) log_ratios.push_back(std::log(all.v[k] / all.s[k]));
  }
  if (log_ratios.size() < kMinMovingSamples) {
    model.reason =
        all.size() == 0 ? "no samples with both speed and frequency" : "too few samples while moving";
    return model;
  }
  bool timed = false;
  std::vector<double> steady = steady_log_ratios(all, timed);
  // In gear the ratio holds from one sample to the next. A timed log in which hardly any sample agrees
  // with a neighbour has no engaged gear to learn from: noise, or two channels that do not belong
  // together (real drives: most moving samples agree; shifts and clutch make the rest).
  constexpr double kMinSteadyShare = 0.1;
  if (timed &&
      static_cast<double>(steady.size()) < kMinSteadyShare * static_cast<double>(log_ratios.size())) {
    model.reason =
        "the speed/frequency ratio hardly ever holds from one sample to the next (no gear engaged)";
    return model;
  }
  if (steady.size() < kMinMovingSamples) steady = log_ratios;
  const MixtureData work = subsample(all, kWorkingSamples);
  const LadderJudge judge(work, all.size(), steady, log_ratios, octave_log_ratios(all));
  std::vector<double> init =
      candidate_scales(steady, static_cast<std::size_t>(std::max(kMaxCandidates, gears)));
  // A forced count larger than the modes found: fill the widest gaps geometrically.
  while (static_cast<int>(init.size()) < gears) {
    std::sort(init.begin(), init.end());
    std::size_t widest = 0;
    for (std::size_t i = 1; i + 1 < init.size(); ++i)
      if (init[i + 1] - init[i] > init[widest + 1] - init[widest]) widest = i;
    init.push_back(init.size() < 2 ? init[0] + 0.3 : 0.5 * (init[widest] + init[widest + 1]));
  }
  // Backward elimination: fit all candidates, then drop one component at a time (an implausible one
  // first, else the lightest), refitting each time; keep the plausible ladder of best BIC.
  MixtureParams p = initial_params(work, init, vmax);
  Candidate best;
  std::string last_reason = "no discrete gear ladder in the data";
  LadderCheck forced;  // what the physics says of a forced count's ladder
  Candidate more;      // with a forced count: the best plausible ladder of more gears met on the way down
  std::vector<double> largest;       // the thetas of the plausible ladder of most gears met on the way down
  std::vector<Candidate> plausible;  // the plausible ladders met on the way down
  while (true) {
    const double ll = run_em(work, p, kEmIterations, 1e-6);
    const LadderCheck verdict = judge.check(p);
    const int m = p.gears();
    if (gears > 0 && m == gears) {
      more = best;
      best = {p, ll, bic_of(ll, m, work.size())};
      forced = verdict;
      break;
    }
    if (verdict.offender < 0 && m >= 2) {
      if (largest.empty()) largest = p.theta;
      const double bic = bic_of(ll, m, work.size());
      if (gears == 0) plausible.push_back({p, ll, bic});
      if (bic < best.bic) best = {p, ll, bic};
    } else if (!verdict.reason.empty()) {
      last_reason = verdict.reason;
    }
    if (m <= std::max(gears, 1)) break;
    int drop = verdict.offender;
    if (drop < 0) drop = static_cast<int>(std::min_element(p.alpha.begin(), p.alpha.end()) - p.alpha.begin());
    p = without(p, drop);
  }
  if (best.params.gears() == 0 && single_gear && gears == 0) best = single_cluster(work, steady, judge, vmax);
  if (gears == 0) best = with_first_gear(best, plausible, judge.idle_freq());
  if (best.params.gears() == 0) {
    model.reason = last_reason;
    return model;
  }
  p = best.params;
  // The subsample chose the ladder; the full data sets the final values.
  if (work.size() < all.size()) (void)run_em(all, p, kFullDataIterations, 1e-9, false);
  GearModel fitted = finish_model(all, p, "auto", GradientLayout{p.gears(), true, p.beta_stand > 0.0});
  fitted.extra["speed_lag"] = aligned.lag;
  if (gears == 0) record_lower_gears(largest, fitted);
  // A forced count is fitted whatever the data shows, but not silently: the ladder's first failing gear
  // and why (a near-empty gear added beside the real ones, clusters too close or too far apart), or the
  // larger plausible ladder that explains the data better (a real gear merged away).
  if (forced.offender >= 0 && static_cast<std::size_t>(forced.offender) < fitted.gears.size()) {
    char what[64];
    std::snprintf(what, sizeof what, "gear %d (theta %.5f): ", forced.offender + 1,
                  fitted.gears[static_cast<std::size_t>(forced.offender)].theta);
    fitted.extra["forced_doubt"] = {{"gear", forced.offender + 1}, {"reason", what + forced.reason}};
  } else if (more.bic < best.bic) {
    fitted.extra["forced_doubt"] = {
        {"gears", more.params.gears()},
        {"reason", std::to_string(more.params.gears()) + " gears explain the data better (BIC)"}};
  }
  return fitted;
}

}  // namespace gearpulse::detail
