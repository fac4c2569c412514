#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/gear_model.hpp"
#include "core/json_depth.hpp"
#include "core/model_extras.hpp"
#include "core/sample.hpp"
#include "core/speed_synth.hpp"
#include "tests/test_util.hpp"

using gearpulse::GearModel;

TEST_CASE("model: JSON round trip keeps gears and noise levels") {
  GearModel m;
  m.gears = {{0.043, 0.05, 0.0002}, {0.072, 0.1, 0.0003}};
  m.sigma_speed = 0.3;
  m.sigma_freq = 1.5;
  m.samples = 2400;
  m.log_likelihood = -1234.5;
  const GearModel back = gearpulse::parse_model(gearpulse::serialize_model(m));
  REQUIRE(back.gears.size() == 2);
  CHECK(back.gears[1].theta == Approx(0.072));
  CHECK(back.gears[0].std_error == Approx(0.0002));
  CHECK(back.samples == 2400);
  CHECK(back.sigma_freq == Approx(1.5));
}

TEST_CASE("model: the JSON lists the contract's keys first, in the order of its example, and extra last") {
  GearModel m;
  m.gears = {{0.043, 0.05, 0.0002}};
  m.method = "auto";
  m.extra["idle"] = {{"freq", 13.1}};
  const std::string text = gearpulse::serialize_model(m);
  std::vector<std::size_t> at;
  for (const char* key :
       {"\"version\"", "\"gears\"", "\"theta\"", "\"weight\"", "\"stderr\"", "\"sigma_speed\"",
        "\"sigma_freq\"", "\"samples\"", "\"log_likelihood\"", "\"method\"", "\"extra\"", "\"idle\""}) {
    at.push_back(text.find(key));
    INFO(key << " in " << text);
    REQUIRE(at.back() != std::string::npos);
  }
  CHECK(std::is_sorted(at.begin(), at.end()));
}

TEST_CASE("model: rejects unordered, non-positive and versionless models") {
  CHECK_THROWS_AS(gearpulse::parse_model(R"({"version":1,"gears":[{"theta":0.1},{"theta":0.05}]})"),
                  std::invalid_argument);
  CHECK_THROWS_AS(gearpulse::parse_model(R"({"version":1,"gears":[{"theta":-0.1}]})"), std::invalid_argument);
  CHECK_THROWS_AS(gearpulse::parse_model(R"({"gears":[]})"), std::invalid_argument);
  CHECK_THROWS_AS(gearpulse::parse_model("not json"), std::invalid_argument);
  CHECK(gearpulse::parse_model(R"({"version":1,"gears":[]})").empty());
}

TEST_CASE("model: rejects what no fit writes: a wrapped version, too many gears, negative noise or weights") {
  const auto rejected = [](const std::string& text) {
    INFO(text);
    CHECK_THROWS_AS(gearpulse::parse_model(text), std::invalid_argument);
  };
  rejected(R"({"version":4294967297,"gears":[]})");  // 2^32 + 1 is not 1
  std::string many = R"({"version":1,"gears":[)";
  for (int i = 1; i <= 13; ++i)
    many += std::string(i > 1 ? "," : "") + R"({"theta":)" + std::to_string(0.05 * i) + "}";
  rejected(many + "]}");
  rejected(R"({"version":1,"gears":[{"theta":0.1}],"sigma_speed":-1})");
  rejected(R"({"version":1,"gears":[{"theta":0.1}],"sigma_freq":-0.5})");
  rejected(R"({"version":1,"gears":[{"theta":0.1,"weight":-0.2}]})");
  rejected(R"({"version":1,"gears":[{"theta":0.1,"weight":1.5}]})");
  rejected(R"({"version":1,"gears":[{"theta":0.1,"stderr":-1}]})");
  rejected(R"({"version":1,"gears":[{"theta":0.1}],"outlier_weight":5})");
  rejected(R"({"version":1,"gears":[{"theta":0.1}],"samples":1e300})");
  // Twelve gears, the most a fit gives, are fine.
  std::string twelve = R"({"version":1,"gears":[)";
  for (int i = 1; i <= 12; ++i)
    twelve += std::string(i > 1 ? "," : "") + R"({"theta":)" + std::to_string(0.05 * i) + "}";
  CHECK(gearpulse::parse_model(twelve + "]}").gears.size() == 12);
}

// A truncated or hand-edited model.json is refused with where it goes wrong, as an editor counts lines
// and columns, after the message's old start (scripts look for "model: not valid JSON").
TEST_CASE("model: JSON that does not parse is refused with its line and column") {
  GearModel m;
  m.gears = {{0.05, 0.5, 0.0002}, {0.09, 0.5, 0.0003}};
  const std::string model = gearpulse::serialize_model(m);
  const std::string truncated = model.substr(0, model.find("\"theta\"", model.find("\"theta\"") + 1));
  const auto lines = static_cast<std::size_t>(std::count(truncated.begin(), truncated.end(), '\n'));
  const std::size_t column = truncated.size() - truncated.rfind('\n');
  CHECK_THROWS_WITH(gearpulse::parse_model(truncated), "model: not valid JSON at line " +
                                                           std::to_string(lines + 1) + ", column " +
                                                           std::to_string(column) + " (the text ends there)");
  CHECK_THROWS_WITH(gearpulse::parse_model("{\"version\": 1,\n \"gears\": [}\n"),
                    "model: not valid JSON at line 2, column 12");
  CHECK_THROWS_WITH(gearpulse::parse_model(""),
                    "model: not valid JSON at line 1, column 1 (the text ends there)");
}

TEST_CASE("model: a field of the wrong type is refused with std::invalid_argument naming it") {
  // A bad model is refused with std::invalid_argument and a readable message (`gearpulse replay` turns
  // just that into an error naming the file): a string or a boolean where a number belongs must be refused
  // the same way, not escape as the JSON library's own exception, nor a boolean be read as 1.
  for (const char* theta : {R"("0.1")", "true"}) {
    const std::string text = std::string(R"({"version":1,"gears":[{"theta":)") + theta + "}]}";
    INFO(text);
    CHECK_THROWS_AS(gearpulse::parse_model(text), std::invalid_argument);
    CHECK_THROWS_WITH(gearpulse::parse_model(text), Catch::Contains("'theta' is not a number"));
  }
}

TEST_CASE("model: an optional field given as null is read as absent") {
  // A program writing a model without a mixture may give its weights as null.
  const GearModel m = gearpulse::parse_model(R"({"version":1,"gears":[{"theta":0.1,"weight":null}]})");
  REQUIRE(m.gears.size() == 1);
  CHECK(m.gears[0].weight == 0.0);
}

TEST_CASE("model: rejects equal thetas, a negative sample count and a negative outlier weight") {
  // Two gears of one ratio are one gear: the synthesis picks a gear by its theta, and the ladder must be
  // strictly ascending (eq. 5).
  CHECK_THROWS_AS(gearpulse::parse_model(R"({"version":1,"gears":[{"theta":0.1},{"theta":0.1}]})"),
                  std::invalid_argument);
  CHECK_THROWS_AS(gearpulse::parse_model(R"({"version":1,"gears":[{"theta":0.1}],"samples":-5})"),
                  std::invalid_argument);
  CHECK_THROWS_AS(gearpulse::parse_model(R"({"version":1,"gears":[{"theta":0.1}],"outlier_weight":-0.5})"),
                  std::invalid_argument);
}

TEST_CASE("model: a model nested exactly 32 levels loads, and one of 33 is refused") {
  // The limit is the most a model may nest: a file at it is read, one level more is not.
  const auto nested = [](int levels) {
    // The object and "extra" are two levels; the arrays inside make up the rest.
    return std::string(R"({"version":1,"gears":[],"extra":{"x":)") + std::string(levels - 2, '[') +
           std::string(levels - 2, ']') + "}}";
  };
  REQUIRE(gearpulse::json_nesting(nested(32)) == 32);
  CHECK_NOTHROW(gearpulse::parse_model(nested(32)));
  REQUIRE(gearpulse::json_nesting(nested(33)) == 33);
  CHECK_THROWS_WITH(gearpulse::parse_model(nested(33)), Catch::Contains("nested deeper than 32 levels"));
}

TEST_CASE("model: a model nested too deep is refused before it is copied") {
  // A 200 kB model.json whose extra nests 100,000 arrays overflowed the stack where the model was copied
  // (the daemon would crash at every start), and one of 40 kB printed as 0.8 GB of indentation.
  const std::string head =
      R"({"version":1,"gears":[{"theta":0.1,"weight":1,"stderr":0}],"sigma_speed":0.1,"sigma_freq":1,)"
      R"("samples":10,"log_likelihood":0,"extra":{"x":)";
  const std::string deep = head + std::string(100000, '[') + std::string(100000, ']') + "}}";
  CHECK_THROWS_WITH(gearpulse::parse_model(deep), Catch::Contains("nested deeper than 32 levels"));
  // As deep as a model goes, and brackets inside strings, which do not nest.
  const std::string fine = head + R"([{"a":"[[[[{{{{\"[[[["},[[]]]}})";
  CHECK(gearpulse::parse_model(fine).extra["x"][0]["a"] == "[[[[{{{{\"[[[[");
  CHECK(gearpulse::json_nesting(R"({"a":[1,{"b":"]]]]"}],"c":[]})") == 3);
  CHECK(gearpulse::json_nesting("12") == 0);
}

TEST_CASE("model: a mangled model file is a model that holds or std::invalid_argument, nothing else") {
  // A model as `fit --out` writes it (with the estimator's extras), mangled at random: characters
  // replaced, dropped or inserted (quotes, brackets, signs, exponents, keys' names), cut short. The daemon
  // reads model.json at every start: whatever is in it must be refused with a reason or hold the
  // invariants the synthesis relies on.
  GearModel m;
  m.gears = {{0.043, 0.05, 0.0002}, {0.072, 0.1, 0.0003}, {0.106, 0.2, 0.0003}, {0.146, 0.3, 0.0004}};
  m.sigma_speed = 0.3;
  m.sigma_freq = 1.5;
  m.samples = 2400;
  m.outlier_weight = 0.12;
  m.method = "auto";
  m.extra["idle"] = {{"freq", 13.1}, {"sd", 0.4}};
  m.extra["revs"] = nlohmann::json::array();
  for (double f : {40.0, 38.0, 35.0, 33.0})
    m.extra["revs"].push_back({{"mean_log", std::log(f)}, {"sd_log", 0.2}, {"samples", 300}});
  const std::string text = gearpulse::serialize_model(m);
  const std::vector<std::string> pieces = {
      "\"",   "{",    "}",         "[",           "]",          ",", ":", "-", "1e999",
      "null", "true", "\"theta\"", "\"version\"", "\"sd_log\"", "0", ".", "e", std::string(1, '\0')};
  std::mt19937 rng(29);
  int parsed = 0, refused = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    const std::string s = gearpulse::test::mangle(text, 1 + static_cast<int>(rng() % 6), pieces, rng);
    INFO(s);
    try {
      const GearModel g = gearpulse::parse_model(s);
      ++parsed;
      REQUIRE(g.gears.size() <= GearModel::kMaxGears);
      double previous = 0.0;
      for (const auto& gear : g.gears) {
        REQUIRE(std::isfinite(gear.theta));
        REQUIRE(gear.theta > previous);
        REQUIRE(gear.weight >= 0.0);
        REQUIRE(gear.weight <= 1.0);
        previous = gear.theta;
      }
      REQUIRE(std::isfinite(g.sigma_speed));
      REQUIRE(g.sigma_speed >= 0.0);
      REQUIRE(std::isfinite(g.sigma_freq));
      REQUIRE(g.sigma_freq >= 0.0);
      // The synthesis takes whatever extras it holds (idle, revs per gear): its speeds stay finite.
      gearpulse::SpeedSynthesizer synth(std::make_shared<const GearModel>(g));
      for (int k = 0; k < 20; ++k) {
        const auto o = synth.step(k, k < 10 ? 8.0 : gearpulse::kMissing, 12.0 + 2.0 * k);
        REQUIRE(std::isfinite(o.speed));
        REQUIRE(o.speed >= 0.0);
      }
    } catch (const std::invalid_argument&) {
      ++refused;
    }
  }
  INFO("parsed " << parsed << ", refused " << refused);
  CHECK(parsed > 0);
  CHECK(refused > 0);
}

TEST_CASE("model: the extras the synthesis reads come out as numbers, the malformed ones unknown") {
  GearModel m;
  m.gears = {{0.043, 0.5, 0.0}, {0.072, 0.5, 0.0}};
  m.extra = nlohmann::json::parse(R"({"speed_lag": 0.4, "idle": {"freq": 27.5, "sd": 1.2},
      "rolling_idle": {"freq": "fast"}, "idle_braking": {"accel": -0.7, "seconds": 90},
      "revs": [{"mean_log": 3.9, "sd_log": 0.2, "samples": 300}, {"mean_log": 4.1}],
      "lower_gears": [0.021, "x", -1, 0.031], "launch_gears": {"base": 0.043, "counts": [7, 10, 0, 0, 1]}})");
  const gearpulse::ModelExtras x = gearpulse::read_model_extras(&m);
  CHECK(x.speed_lag == Approx(0.4));
  CHECK(x.idle_freq == Approx(27.5));
  CHECK(x.idle_sd == Approx(1.2));
  CHECK(std::isnan(x.rolling_idle));
  CHECK(x.idle_braking_accel == Approx(-0.7));
  CHECK(x.idle_braking_seconds == Approx(90.0));
  REQUIRE(x.has_revs);
  CHECK(x.revs[0].samples == Approx(300.0));
  CHECK(x.revs[1].mean_log == Approx(4.1));
  CHECK(std::isnan(x.revs[1].sd_log));
  REQUIRE(x.lower_count == 2);
  CHECK(x.lower_gears[1] == Approx(0.031));
  CHECK(x.launch_base == Approx(0.043));
  CHECK(x.launch_counts[1] == Approx(10.0));
  CHECK(x.launch_counts[4] == Approx(1.0));
  // Launch counts of another length or with a count that is no number are none.
  GearModel bad = m;
  bad.extra["launch_gears"] = nlohmann::json::parse(R"({"base": 0.043, "counts": [7, 10]})");
  CHECK(gearpulse::read_model_extras(&bad).launch_base == 0.0);
  bad.extra["launch_gears"] = nlohmann::json::parse(R"({"base": 0.043, "counts": [7, "x", 0, 0, 0]})");
  const gearpulse::ModelExtras refused = gearpulse::read_model_extras(&bad);
  CHECK(refused.launch_base == 0.0);
  CHECK(refused.launch_counts[0] == 0.0);
  // Revs for another count of gears belong to another ladder: none is read.
  m.gears.push_back({0.1, 0.2, 0.0});
  CHECK_FALSE(gearpulse::read_model_extras(&m).has_revs);
  // No model, or an extra that is no object: nothing known, no lag.
  CHECK(std::isnan(gearpulse::read_model_extras(nullptr).idle_freq));
  m.extra = nlohmann::json::array({1, 2});
  const gearpulse::ModelExtras none = gearpulse::read_model_extras(&m);
  CHECK(none.speed_lag == 0.0);
  CHECK_FALSE(none.has_revs);
  CHECK(none.lower_count == 0);
}
