#include <catch2/catch.hpp>

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "tools/sim/nmea.hpp"

using gearpulse::sim::epochs_at_1hz;
using gearpulse::sim::make_nmea_log;
using gearpulse::sim::nmea_sentence;

namespace {

std::vector<std::string> fields(const std::string& sentence) {
  std::vector<std::string> out;
  std::stringstream ss(sentence.substr(1, sentence.find('*') - 1));
  std::string f;
  while (std::getline(ss, f, ','))
    out.push_back(f);
  return out;
}

}  // namespace

TEST_CASE("nmea: checksums match a real receiver's sentences") {
  // Sentences from gpsd's test logs (data/real/gpsd-nmea), checksums as the receivers wrote them.
  CHECK(nmea_sentence("GPRMC,,V,,,,,,,,,,N") == "$GPRMC,,V,,,,,,,,,,N*53\r\n");
  CHECK(nmea_sentence("GPGGA,,,,,,0,00,99.99,,,,,,") == "$GPGGA,,,,,,0,00,99.99,,,,,,*48\r\n");
  CHECK(nmea_sentence("GPRMC,094737,A,5251.0093,N,00518.8170,E,5.6,230.5,200818,1.4,E,A") ==
        "$GPRMC,094737,A,5251.0093,N,00518.8170,E,5.6,230.5,200818,1.4,E,A*1F\r\n");
}

TEST_CASE("nmea: two sentences per epoch with speed in knots and void epochs for outages") {
  const double nan = std::nan("");
  const std::vector<double> speeds = {10.0, 20.0, nan, 5.0};
  const auto lines = make_nmea_log(epochs_at_1hz(speeds), {});
  REQUIRE(lines.size() == 8);
  for (std::size_t i = 0; i < speeds.size(); ++i) {
    const auto rmc = fields(lines[2 * i]);
    const auto gga = fields(lines[2 * i + 1]);
    REQUIRE(rmc[0] == "GPRMC");
    REQUIRE(gga[0] == "GPGGA");
    CHECK(rmc[1] == gga[1]);  // same epoch time
    if (std::isnan(speeds[i])) {
      CHECK(rmc[2] == "V");
      CHECK(gga[6] == "0");
    } else {
      CHECK(rmc[2] == "A");
      CHECK(gga[6] == "1");
      CHECK(std::stod(rmc[7]) * 1852.0 / 3600.0 == Approx(speeds[i]).margin(0.0003));
    }
    // Each line ends in its own valid checksum.
    const std::string& l = lines[2 * i];
    CHECK(nmea_sentence(l.substr(1, l.find('*') - 1)) == l);
  }
  // Heading east: longitude grows with distance driven, latitude stays.
  CHECK(fields(lines[2])[5] > fields(lines[0])[5]);
  CHECK(fields(lines[2])[3] == fields(lines[0])[3]);
}
