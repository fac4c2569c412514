#include "core/model_extras.hpp"

#include <cmath>

namespace gearpulse {
namespace {

// A number under `key` of a JSON object; NaN if absent or not a number.
double extra_number(const nlohmann::json& j, const char* key) noexcept {
  if (!j.is_object()) return std::numeric_limits<double>::quiet_NaN();
  const auto it = j.find(key);
  return it != j.end() && it->is_number() ? it->get<double>() : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace

ModelExtras read_model_extras(const GearModel* model) noexcept {
  ModelExtras x;
  if (model == nullptr || !model->extra.is_object()) return x;
  const nlohmann::json& extra = model->extra;
  if (const double lag = extra_number(extra, "speed_lag"); std::isfinite(lag)) x.speed_lag = lag;
  if (const auto idle = extra.find("idle"); idle != extra.end()) {
    x.idle_freq = extra_number(*idle, "freq");
    x.idle_sd = extra_number(*idle, "sd");
  }
  if (const auto rolling = extra.find("rolling_idle"); rolling != extra.end())
    x.rolling_idle = extra_number(*rolling, "freq");
  if (const auto braking = extra.find("idle_braking"); braking != extra.end()) {
    x.idle_braking_accel = extra_number(*braking, "accel");
    x.idle_braking_seconds = extra_number(*braking, "seconds");
  }
  if (const auto revs = extra.find("revs"); revs != extra.end() && revs->is_array() &&
                                            revs->size() == model->gears.size() &&
                                            revs->size() <= x.revs.size()) {
    x.has_revs = true;
    for (std::size_t i = 0; i < revs->size(); ++i) {
      const nlohmann::json& r = (*revs)[i];
      x.revs[i] = {extra_number(r, "mean_log"), extra_number(r, "sd_log"), extra_number(r, "samples")};
    }
  }
  if (const auto lower = extra.find("lower_gears"); lower != extra.end() && lower->is_array()) {
    for (const auto& v : *lower)
      if (v.is_number() && v.get<double>() > 0.0 && x.lower_count < x.lower_gears.size())
        x.lower_gears[x.lower_count++] = v.get<double>();
  }
  if (const auto launches = extra.find("launch_gears"); launches != extra.end() && launches->is_object()) {
    const double base = extra_number(*launches, "base");
    const auto counts = launches->find("counts");
    if (std::isfinite(base) && base > 0.0 && counts != launches->end() && counts->is_array() &&
        counts->size() == x.launch_counts.size()) {
      bool valid = true;
      for (std::size_t k = 0; k < counts->size(); ++k) {
        const nlohmann::json& c = (*counts)[k];
        valid = valid && c.is_number() && c.get<double>() >= 0.0;
        if (valid) x.launch_counts[k] = c.get<double>();
      }
      if (valid)
        x.launch_base = base;
      else
        x.launch_counts.fill(0.0);
    }
  }
  return x;
}

}  // namespace gearpulse
