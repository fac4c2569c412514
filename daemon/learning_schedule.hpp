#pragma once
// When a young model is refitted. A new install learns early, then settles: the first fit as soon as the
// training pairs show one gear clearly (a cluster of steady pairs), refits after first_refit, 2 x, 4 x ...
// that time of moving while the model is young and as soon as they show a gear the model lacks, then the
// retrainer's interval rule. The clock is the
// moving time the training pairs cover, so the schedule is the same whether the pairs arrive live or are
// replayed, and a store cleared by a reset starts it again.
#include <cstddef>
#include <optional>
#include <span>

#include "core/gear_model.hpp"
#include "core/sample.hpp"

namespace gearpulse::daemon {

struct LearningSettings {
  std::size_t cluster_pairs = 40;  // steady pairs in one gear's window before the first fit
  double first_refit = 60.0;       // s of moving at the first refit; each next one at twice that
  double young_time = 960.0;       // s of moving the schedule lasts (its last refit); 0 = no schedule
};

// What the schedule reads from the training pairs.
struct PairsSummary {
  double moving_time = 0.0;         // s: steps between consecutive pairs both moving, each up to kMaxStep
  std::size_t largest_cluster = 0;  // steady pairs in the densest gear window (largest_gear_cluster)
  // The same, of the steady pairs off the model's lines (none within a gearbox step, 2 x kGearWindow, of
  // one of its gears): a gear the model does not have yet. Without a model, largest_cluster.
  std::size_t new_gear_cluster = 0;
  std::size_t model_gears = 0;  // gears of the model they were read against

  static constexpr double kMaxStep = 10.0;  // s: a longer step is a stop or a gap, not driving
};

[[nodiscard]] PairsSummary summarize_pairs(std::span<const Sample> pairs, const GearModel* model = nullptr);

class LearningSchedule {
 public:
  explicit LearningSchedule(LearningSettings settings = {}) noexcept : settings_(settings) {}

  void set_settings(LearningSettings settings) noexcept { settings_ = settings; }
  [[nodiscard]] const LearningSettings& settings() const noexcept { return settings_; }

  // Young: the schedule decides the fits, until young_time of moving (with a model whose schedule ran,
  // until the fit at young_time has been tried).
  [[nodiscard]] bool young(const PairsSummary& pairs, bool has_model) const noexcept;
  // A fit is due now: without a model, when the densest gear window holds cluster_pairs (again, after a
  // fit that found nothing, once it has grown by half that or a refit time has passed); with a model, when
  // a refit time has passed since the last fit tried, or when the densest window off the model's gears
  // holds a quarter of cluster_pairs (again, after a fit that did not add that gear, once it has grown by
  // a quarter more).
  [[nodiscard]] bool due(const PairsSummary& pairs, bool has_model) const noexcept;
  // A fit was tried on pairs so summarised.
  void tried(const PairsSummary& pairs) noexcept;
  // Moving time (s) of the next refit after `moving_time`, none once the schedule is over.
  [[nodiscard]] std::optional<double> next_refit(double moving_time) const noexcept;
  // Forget the fits tried (the training pairs were cleared).
  void restart() noexcept { last_ = {}; }

 private:
  // The latest refit time at or before `moving_time`, none before the first.
  [[nodiscard]] std::optional<double> passed_refit(double moving_time) const noexcept;

  LearningSettings settings_;
  std::optional<PairsSummary> last_;  // the pairs of the last fit tried
};

}  // namespace gearpulse::daemon
