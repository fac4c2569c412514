// The gears that join the synthesis's ladder (SpeedSynthesizer, core/speed_synth.hpp; loaded in
// synth_ladder.cpp): those measured under GPS that the model lacks, the gears below a ladder that lacks first
// gear (the fit's dropped ones, then predicted ones), and those predicted inside and above a young ladder.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <span>

#include "core/estimator.hpp"
#include "core/speed_synth.hpp"
#include "core/synth_constants.hpp"

namespace gearpulse {
using namespace synth;
namespace {

// The factor by which a gearbox's steps (log theta ratios) grow from one gear to the next lower, as the
// gears predicted below the ladder and inside it take it from the steps above them: progressive, so at
// least 1; at most 1.5, the fewest gears predicted where the steps grow faster.
constexpr double kMinGrowth = 1.0, kMaxGrowth = 1.5;
// The largest step (log theta ratio) of a gearbox: first to second gear in a four-speed box, a factor of 2.
constexpr double kMaxGearStep = std::numbers::ln2;

// The upper end of the revs the fit saw in gear `index` of the model (ln Hz: extra.revs' mean_log plus
// sd_log), NaN where the model does not say or saw the gear on fewer than `min_samples` pairs.
double fitted_revs_top(const ModelExtras& extras, std::size_t index, double min_samples) noexcept {
  const ModelExtras::GearRevs& r = extras.revs[index];
  return r.samples >= min_samples ? r.mean_log + r.sd_log : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace

// The gears seen under GPS that the model lacks (seen_) join its ladder in theta order, each used for its
// share of the steady fixes seen, while there is room and the model has a ladder at all; one seen only at
// lugged revs as a possible creep (creep_, lugging()).
void SpeedSynthesizer::insert_seen_gears() noexcept {
  if (gears_ == 0) return;
  std::array<SeenGears::Gear, SeenGears::kCapacity> seen{};
  const int n = seen_.seen(seen);
  for (int k = 0; k < n && gears_ < kMaxGears; ++k) {
    const SeenGears::Gear& g = seen[static_cast<std::size_t>(k)];
    bool known = false;
    for (int j = 1; j <= gears_; ++j)
      known = known || std::abs(std::log(g.theta / theta_[j])) < 2.0 * kGearWindow;
    if (known) continue;
    const int at = insert_in_ladder(g.theta, g.std_error, std::max(g.share, kMinGearShare), 0);
    if (at > 0 && g.creep && tuning_.creep_gears > 0.0) creep_[at] = 1.0;
  }
}

// The ladder's gears from position `from` up move `by` positions higher, with everything kept per position.
void SpeedSynthesizer::shift_ladder(int from, int by) noexcept {
  for (int j = gears_; j >= from; --j) {
    theta_[j + by] = theta_[j];
    theta_se_[j + by] = theta_se_[j];
    weight_[j + by] = weight_[j];
    model_gear_[j + by] = model_gear_[j];
    creep_[j + by] = creep_[j];
  }
}

// One gear joins the ladder in theta order; a full ladder (kMaxGears) takes none: its gears and the
// moving-off mode above them fill the mode arrays.
int SpeedSynthesizer::insert_in_ladder(double theta, double theta_se, double weight,
                                       int model_gear) noexcept {
  if (gears_ >= kMaxGears) return 0;
  int at = gears_ + 1;  // ladder position it takes
  for (int j = gears_; j >= 1 && theta < theta_[j]; --j)
    at = j;
  shift_ladder(at, 1);
  creep_[at] = 0.0;
  theta_[at] = theta;
  theta_se_[at] = theta_se;
  weight_[at] = weight;
  model_gear_[at] = model_gear;
  ++gears_;
  return at;
}

// Whether a gear seen under GPS that the model lacks lies within `half` (in log theta) of `theta`: such a
// gear stands for a gear predicted there.
bool SpeedSynthesizer::seen_gear_near(double theta, double half) const noexcept {
  for (int j = 1; j <= gears_; ++j)
    if (model_gear_[j] == 0 && std::abs(std::log(theta_[j] / theta)) < half) return true;
  return false;
}

// A young model lacks the gears not yet driven steadily, and those may lie between gears it has: the
// gears passed in a launch, between a low gear driven steadily (creeping in town) and the cruising gears.
// A gearbox is progressive: its steps (log theta ratios) do not shrink toward the low gears. A gear missing
// in a step of the model's ladder thus makes that step the sum of two gearbox steps or more, each at least
// the step above it: a step twice the one above it or more is taken to lack gears, one under that lacks
// none (the steps of the gearboxes known here grow by a factor of 1.1 to 1.9 from one gear to the next
// lower). How many it lacks is read from the steps above it, as for the gears predicted below the ladder
// (predict_lower_gears): the steps down from the one above it grow by the factor that step grew by over
// the one above it (between 1 and 1.5), and the count whose sum comes nearest the step in ratio is taken;
// with no step above it to measure the growth by, gap_step_growth (the middle of that range). The gears go
// where those steps, scaled to fill the step exactly, put them.
// Only the model's own steps are judged: a gear seen under GPS (insert_seen_gears, at sparse cadences
// sometimes a ratio no gear has) stands for the predicted gear within half a predicted step of it. Each
// predicted gear is used as the less used of the model's gears beside it (gap_gear_share: it lies among gears
// driven steadily, not below them, where a launch passes a gear in a second; with the least share it was left
// within seconds for a gear the speed could reach in that time), and has no standard error of theta (as those
// predicted below the ladder) and no number in the model.
void SpeedSynthesizer::insert_gap_gears() noexcept {
  if (model_ == nullptr) return;
  std::array<double, kMaxGears> thetas{};
  const std::span<const double> model = thetas_of(model_.get(), thetas);
  const int m = static_cast<int>(model.size());
  if (m < 2) return;
  const auto step = [&](int k) {
    return std::log(model[static_cast<std::size_t>(k + 1)] / model[static_cast<std::size_t>(k)]);
  };
  ModeArray gap{}, share{};  // predicted thetas, any order, and their shares of use
  // A gear predicted inside the ladder is used as the less used of the model's gears beside it
  // (gap_gear_share), or for the least share.
  const auto share_beside = [&](int k) {
    return tuning_.gap_gear_share > 0.0
               ? std::max(std::min(model_->gears[static_cast<std::size_t>(k)].weight,
                                   model_->gears[static_cast<std::size_t>(k + 1)].weight),
                          kMinGearShare)
               : kMinGearShare;
  };
  int n_gap = 0;
  // A gear predicted at `theta` in the step above the model's gear `k`, unless a gear seen under GPS within
  // `half` of it stands for it.
  const auto add_gap = [&](double theta, double half, int k) {
    if (seen_gear_near(theta, half)) return;
    share[static_cast<std::size_t>(n_gap)] = share_beside(k);
    gap[static_cast<std::size_t>(n_gap++)] = theta;
  };
  for (int k = 0; tuning_.fill_ladder_gaps > 0.0 && k + 1 < m; ++k) {
    const double size = step(k);
    // A gear missing in this step makes it the sum of two gearbox steps at least, each no smaller than the
    // step above it: a step under twice the one above it lacks no gear.
    if (k + 2 >= m || size < 2.0 * step(k + 1)) continue;
    const double ref = step(k + 1);
    const double growth =
        k + 3 < m ? std::clamp(ref / step(k + 2), kMinGrowth, kMaxGrowth) : tuning_.gap_step_growth;
    const int room = kMaxGears - gears_ - n_gap;
    int best = 1;
    double sum = ref * growth, best_sum = sum, miss = std::abs(std::log(size / sum));
    double next = ref * growth;
    for (int n = 2; n <= room + 1; ++n) {
      next *= growth;
      sum += next;
      const double d = std::abs(std::log(size / sum));
      if (n > 2 && d >= miss) break;
      best = n, best_sum = sum, miss = d;
    }
    if (best < 2) continue;
    // The predicted gears from the top of the step down, each step scaled to fill it.
    const double scale = size / best_sum;
    const double half = 0.5 * scale * ref * growth;  // half the smallest predicted step
    double part = ref, down = 0.0;
    for (int i = 1; i < best; ++i) {
      part *= growth;
      down += part * scale;
      const double theta = model[static_cast<std::size_t>(k + 1)] * std::exp(-down);
      add_gap(theta, half, k);
    }
  }
  // The top step: steps shrink toward the top gears, so a top step larger than the step below it by more
  // than steps grow from one gear to the next (kMaxGrowth) lacks gears; with no step below it, a top step
  // larger than any gearbox step (kMaxGearStep) does. The gears it lacks are the fewest that make its steps
  // no larger than the step below it (that bound), placed at equal steps.
  if (tuning_.fill_top_step > 0.0) {
    const double size = step(m - 2);
    const double bound = m >= 3 ? step(m - 3) : kMaxGearStep;
    const bool lacks = m >= 3 ? size > kMaxGrowth * bound : size > bound;
    const int room = kMaxGears - gears_ - n_gap;
    const int steps = lacks ? std::min(static_cast<int>(std::ceil(size / bound)), room + 1) : 1;
    const double each = size / steps, half = 0.5 * each;
    for (int i = 1; i < steps; ++i) {
      const double theta = model[static_cast<std::size_t>(m - 2)] * std::exp(i * each);
      add_gap(theta, half, m - 2);
    }
  }
  for (int i = 0; i < n_gap; ++i)
    insert_in_ladder(gap[static_cast<std::size_t>(i)], 0.0, share[static_cast<std::size_t>(i)], 0);
}

// A ladder that lacks first gear (lacks_first_gear) has gears below its lowest. Where the fit met a
// plausible ladder of more gears that held some below it (the model's extra.lower_gears: their pairs were
// too few for BIC), those join the ladder, each with the least share of use and no number in the model: the
// fit's evidence of where they are, where the ladder's steps only predict it (insert_predicted_gears,
// which goes on below them while the ladder still lacks first gear).
void SpeedSynthesizer::insert_fitted_lower_gears() noexcept {
  if (tuning_.fitted_lower_gears <= 0.0 || model_ == nullptr || gears_ == 0 || !lacks_first_gear()) return;
  const double below = theta_[1] * std::exp(-2.0 * kGearWindow);  // off the lowest by a gearbox step
  std::array<double, kMaxGears> lower{};
  int n = 0;
  for (std::size_t i = 0; i < extras_.lower_count; ++i)
    if (const double theta = extras_.lower_gears[i]; theta < below && n < kMaxGears - gears_)
      lower[static_cast<std::size_t>(n++)] = theta;
  std::sort(lower.begin(), lower.begin() + n);
  insert_below_ladder({lower.data(), static_cast<std::size_t>(n)});
}

// Gears of no number in the model join the ladder below its lowest (`thetas` ascending), each with the
// least share of use and no standard error of theta.
void SpeedSynthesizer::insert_below_ladder(std::span<const double> thetas) noexcept {
  const int n = static_cast<int>(thetas.size());
  if (n == 0) return;
  shift_ladder(1, n);
  for (int k = 0; k < n; ++k) {
    theta_[k + 1] = thetas[static_cast<std::size_t>(k)];
    theta_se_[k + 1] = 0.0;
    weight_[k + 1] = kMinGearShare;
    model_gear_[k + 1] = 0;
    creep_[k + 1] = 0.0;
  }
  gears_ += n;
}

// A ladder that lacks first gear (lacks_first_gear) lacks the gears below its lowest: a young model has
// not seen the launch gears steady. A gearbox's steps grow toward its low gears (a progressive design: the
// engine's usable band covers less of a road speed's range there), so the gears below are predicted from
// the ladder's two lowest steps: the next step down grows by the factor the lowest step grew by over the
// one above it (1 with only one step known), between a factor of 1.06 (the smallest step a fit accepts)
// and 2 (the largest gearbox step, first to second in a four-speed box). Gears are predicted until the
// lowest carries the car at the warm idle no faster than first gear does, and then as many below the base
// as the launches seen under GPS show (launch_gears.hpp): more, or fewer where they show the base is first
// though the idle says otherwise (the idle's bound is a car's: a motorcycle idles higher). The ladder's gears
// from position `base` up are the ones known; the predicted thetas go to `theta`, lowest last. Returns how
// many.
int SpeedSynthesizer::predict_lower_gears(int base, ModeArray& theta) const noexcept {
  const int known = gears_ - base + 1;
  if (tuning_.predict_lower_gears <= 0.0 || known < 2) return 0;
  const double min_step = 2.0 * kGearWindow, max_step = std::log(2.0);
  const double low_step = std::log(theta_[base + 1] / theta_[base]);
  const double growth = known >= 3 ? std::clamp(low_step / std::log(theta_[base + 2] / theta_[base + 1]),
                                                kMinGrowth, kMaxGrowth)
                                   : 1.0;
  double step = std::clamp(low_step, min_step, max_step);
  double lowest = theta_[base];
  int n = 0;
  int wanted = -1;  // gears the launches show below the base, once the idle's are predicted (-1: not asked)
  while (known + n < kMaxGears) {
    if (!habits_.lacks_first_gear(lowest, tuning_)) {
      if (wanted < 0)
        wanted =
            tuning_.launch_gears > 0.0 ? launches_.gears_below(theta_[base], n, tuning_.launch_second) : n;
      if (n >= wanted) break;
    }
    step = std::clamp(step * growth, min_step, max_step);
    lowest /= std::exp(step);
    theta[static_cast<std::size_t>(n)] = lowest;
    ++n;
  }
  return wanted >= 0 ? std::min(n, wanted) : n;  // the launches may show fewer than the idle asks
}

// The predicted gears (predict_lower_gears) join the ladder below its lowest gear, each with the least share
// of use. Their readings carry no standard error of theta: a predicted theta's error is a bias of the speed
// read in that gear, the same at every reading, and spread over the readings as their noise it blurred the
// revs' drops at the launch's shifts, which the filter climbs the predicted gears by.
void SpeedSynthesizer::insert_predicted_gears() noexcept {
  ModeArray theta{};
  const int n = predict_lower_gears(1, theta);
  predicted_ = n;
  std::reverse(theta.begin(), theta.begin() + n);  // the last predicted is the lowest
  insert_below_ladder({theta.data(), static_cast<std::size_t>(n)});
}

// A young model lacks the gears not yet driven steadily, and those may lie above its top gear: a car that
// has driven in town only has not yet cruised in its tall gears, and an outage on its first open road is
// read in the ladder's top gear, too slow by the missing step. A gearbox's steps (log theta ratios) shrink
// toward its top gears, where the engine's band of revs covers a wider span of road speeds (the mirror of
// predict_lower_gears): the next step up is the model's top step shrunk by the factor the step below it
// grew by over it (1 when the model has two gears; between 1 and 1.5), at least a factor of 1.06 (the
// smallest step a fit accepts). At most predict_upper_gears gears are predicted, and only while the
// highest carries the car at the warm idle slower than any top gear does (top_gear_idle_speed); none while
// no idle is known. None either unless the fit saw the model's top gear run no higher than the gear below
// it (top_gear_revs; the upper ends of their bands, extra.revs' mean_log + sd_log): a driver leaves a gear
// for the next before its revs pass his usual band, so a gear run higher than the one below it is one he
// had no gear to leave for; and a model that records no revs gives the predicted gear no band to run in
// (insert_upper_gears). The predicted thetas go to `theta`, lowest first. Returns how many.
int SpeedSynthesizer::predict_upper_gears(ModeArray& theta) const noexcept {
  if (tuning_.predict_upper_gears <= 0.0 || model_ == nullptr) return 0;
  std::array<double, kMaxGears> thetas{};
  const std::span<const double> model = thetas_of(model_.get(), thetas);
  const int m = static_cast<int>(model.size());
  if (m < 2) return 0;
  if (tuning_.top_gear_revs > 0.0 && !top_gear_below_band_) return 0;
  if (!(top_gear_samples_ < tuning_.upper_gear_samples)) return 0;
  const auto at = [&](int k) { return model[static_cast<std::size_t>(k)]; };
  const double top_step = std::log(at(m - 1) / at(m - 2));
  const double growth =
      m >= 3 ? std::clamp(std::log(at(m - 2) / at(m - 3)) / top_step, kMinGrowth, kMaxGrowth) : 1.0;
  const double min_step = 2.0 * kGearWindow;
  double step = std::max(top_step, min_step), highest = at(m - 1);
  int n = 0;
  while (m + n < kMaxGears && n < tuning_.predict_upper_gears) {
    const double speed = habits_.idle_speed(highest);
    if (!(speed < tuning_.top_gear_idle_speed)) break;  // also while no idle is known
    step = std::max(step / growth, min_step);
    highest *= std::exp(step);
    theta[static_cast<std::size_t>(n++)] = highest;
  }
  return n;
}

// Whether the fit saw the model's top gear run no higher than the gear below it (predict_upper_gears), read
// once per model: false where the model records no revs for either.
void SpeedSynthesizer::read_top_gear_revs() noexcept {
  constexpr double kMinSamples = 5.0;  // the fewest a fit accepts a gear on
  const std::size_t m = model_ ? model_->gears.size() : 0;
  top_gear_below_band_ =
      m >= 2 && fitted_revs_top(extras_, m - 1, kMinSamples) <= fitted_revs_top(extras_, m - 2, kMinSamples);
  top_gear_samples_ = m >= 1 ? extras_.revs[m - 1].samples : 0.0;
  if (!std::isfinite(top_gear_samples_)) top_gear_samples_ = 0.0;
}

// The gears predicted above the model's top (predict_upper_gears) join the ladder with no standard error of
// theta and no number in the model, as those predicted below it, each used as the model's top gear is (its
// share of use, and its revs band: load_model): a top gear is a cruising gear, held for minutes on an open
// road at the revs this driver cruises at, where the least share (a launch gear's) has it left within
// seconds, and the driver's revs at large let it take a car rolling at idle revs. A gear seen under GPS
// within half a predicted step of one stands for it.
void SpeedSynthesizer::insert_upper_gears() noexcept {
  ModeArray theta{};
  const int n = predict_upper_gears(theta);
  predicted_above_ = n;
  upper_ = 0;
  double below = model_ && !model_->gears.empty() ? model_->gears.back().theta : 0.0;
  double top_share = kMinGearShare;  // the model's top gear's
  for (int j = 1; j <= gears_; ++j)
    if (model_gear_[j] > 0) top_share = weight_[j];
  for (int i = 0; i < n; ++i) {
    const double t = theta[static_cast<std::size_t>(i)];
    const double half = 0.5 * std::log(t / below);
    below = t;
    if (seen_gear_near(t, half)) continue;
    insert_in_ladder(t, 0.0, top_share, 0);
    upper_theta_[static_cast<std::size_t>(upper_++)] = t;
  }
}

}  // namespace gearpulse
