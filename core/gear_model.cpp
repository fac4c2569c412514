#include "core/gear_model.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "core/json_depth.hpp"

namespace gearpulse {
namespace {

// An optional field may also be null (read as absent), as a program writing a model without a mixture may
// give it.
double finite_number(const nlohmann::json& obj, const char* key, bool required) {
  const auto it = obj.find(key);
  if (it == obj.end() || (!required && it->is_null())) {
    if (required) throw std::invalid_argument(std::string("model: missing field '") + key + "'");
    return 0.0;
  }
  if (!it->is_number())
    throw std::invalid_argument(std::string("model: field '") + key + "' is not a number");
  const double value = it->get<double>();
  if (!std::isfinite(value))
    throw std::invalid_argument(std::string("model: field '") + key + "' is not finite");
  return value;
}

// Where a parse error is, as an editor shows it: "at line L, column C" of `text` for the 1-based byte
// `byte` nlohmann names (one past the end when the text ended early, as a truncated file does).
std::string text_position(std::string_view text, std::size_t byte) {
  const std::size_t at = std::min(std::max<std::size_t>(byte, 1), text.size() + 1) - 1;
  const std::string_view before = text.substr(0, at);
  const std::size_t line = 1 + static_cast<std::size_t>(std::count(before.begin(), before.end(), '\n'));
  const std::size_t newline = before.rfind('\n');  // npos + 1 == 0: the first line starts the text
  return "at line " + std::to_string(line) + ", column " + std::to_string(at - (newline + 1) + 1) +
         (at == text.size() ? " (the text ends there)" : "");
}

}  // namespace

nlohmann::json model_to_json(const GearModel& model) {
  nlohmann::json gears = nlohmann::json::array();
  for (const Gear& g : model.gears) {
    gears.push_back({{"theta", g.theta}, {"weight", g.weight}, {"stderr", g.std_error}});
  }
  // The contract's fields are numbers whatever the fit found: without a gear ladder no mixture was fitted,
  // its figures stay 0 and `fitted` (an added field) says they are not estimates.
  nlohmann::json out = {{"version", GearModel::kVersion},
                        {"gears", std::move(gears)},
                        {"sigma_speed", model.sigma_speed},
                        {"sigma_freq", model.sigma_freq},
                        {"samples", model.samples},
                        {"log_likelihood", model.log_likelihood},
                        {"outlier_weight", model.outlier_weight},
                        {"fitted", !model.gears.empty()}};
  if (!model.method.empty()) out["method"] = model.method;
  if (!model.reason.empty()) out["reason"] = model.reason;
  if (!model.extra.empty()) out["extra"] = model.extra;
  return out;
}

GearModel model_from_json(const nlohmann::json& json) {
  if (!json.is_object()) throw std::invalid_argument("model: not a JSON object");
  if (!json.contains("version") || !json["version"].is_number_integer() ||
      json["version"].get<std::int64_t>() != GearModel::kVersion) {
    throw std::invalid_argument("model: unsupported or missing version (expected 1)");
  }
  if (!json.contains("gears") || !json["gears"].is_array())
    throw std::invalid_argument("model: 'gears' is not a list");
  if (json["gears"].size() > GearModel::kMaxGears)
    throw std::invalid_argument("model: more than " + std::to_string(GearModel::kMaxGears) + " gears");
  GearModel model;
  double previous = 0.0;
  for (const auto& g : json["gears"]) {
    if (!g.is_object()) throw std::invalid_argument("model: a gear is not an object");
    Gear gear;
    gear.theta = finite_number(g, "theta", true);
    gear.weight = finite_number(g, "weight", false);
    gear.std_error = finite_number(g, "stderr", false);
    if (gear.weight < 0.0 || gear.weight > 1.0)
      throw std::invalid_argument("model: a gear's weight is outside [0, 1]");
    if (gear.std_error < 0.0) throw std::invalid_argument("model: a gear's stderr is negative");
    if (gear.theta <= previous)
      throw std::invalid_argument("model: theta must be positive and ascending (eq. 5)");
    previous = gear.theta;
    model.gears.push_back(gear);
  }
  model.sigma_speed = finite_number(json, "sigma_speed", false);
  model.sigma_freq = finite_number(json, "sigma_freq", false);
  if (model.sigma_speed < 0.0 || model.sigma_freq < 0.0)
    throw std::invalid_argument("model: 'sigma_speed' and 'sigma_freq' must not be negative");
  const double samples = finite_number(json, "samples", false);
  if (samples < 0 || samples > 1e15) throw std::invalid_argument("model: 'samples' is outside [0, 1e15]");
  model.samples = static_cast<std::size_t>(samples);
  model.log_likelihood = finite_number(json, "log_likelihood", false);
  model.outlier_weight = finite_number(json, "outlier_weight", false);
  if (model.outlier_weight < 0.0 || model.outlier_weight > 1.0)
    throw std::invalid_argument("model: 'outlier_weight' is outside [0, 1]");
  if (auto it = json.find("method"); it != json.end() && it->is_string())
    model.method = it->get<std::string>();
  if (auto it = json.find("reason"); it != json.end() && it->is_string())
    model.reason = it->get<std::string>();
  if (auto it = json.find("extra"); it != json.end() && it->is_object()) model.extra = *it;
  return model;
}

std::string serialize_model(const GearModel& model) {
  // The contract's keys first, in the order of its example (and a gear's theta, weight, stderr), the added
  // ones after them and `extra` last: a model read by eye, or by a script line by line, starts as
  // documented.
  const nlohmann::json json = model_to_json(model);
  nlohmann::ordered_json out;
  for (const char* key : {"version", "gears", "sigma_speed", "sigma_freq", "samples", "log_likelihood"})
    out[key] = nullptr;
  out["gears"] = nlohmann::ordered_json::array();
  for (const auto& gear : json["gears"])
    out["gears"].push_back(
        {{"theta", gear["theta"]}, {"weight", gear["weight"]}, {"stderr", gear["stderr"]}});
  for (const auto& [key, value] : json.items())
    if (key != "gears" && key != "extra") out[key] = nlohmann::ordered_json(value);
  if (json.contains("extra")) out["extra"] = nlohmann::ordered_json(json["extra"]);  // the long one last
  return out.dump(2) + "\n";
}

GearModel parse_model(std::string_view text) {
  // A model nests four levels (extra.revs[i]); one nested deeper is refused before it is parsed: copied or
  // printed, a deep one overflowed the stack (a 200 kB file at start-up) or grew to gigabytes of text.
  constexpr std::size_t kMaxNesting = 32;
  if (json_nesting(text) > kMaxNesting)
    throw std::invalid_argument("model: nested deeper than " + std::to_string(kMaxNesting) + " levels");
  nlohmann::json json;
  try {
    json = nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    throw std::invalid_argument("model: not valid JSON " + text_position(text, e.byte));
  } catch (const nlohmann::json::exception& e) {
    // A number beyond a double ("number overflow parsing '1e9991'"): the library's words, not its tag.
    const std::string_view what = e.what();
    const std::size_t tag = what.find("] ");
    throw std::invalid_argument("model: not valid JSON: " +
                                std::string(tag == std::string_view::npos ? what : what.substr(tag + 2)));
  }
  return model_from_json(json);
}

}  // namespace gearpulse
