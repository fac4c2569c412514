#include <catch2/catch.hpp>

#include <string>

#include "core/gear_model.hpp"

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
