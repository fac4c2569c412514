#include "tools/sim/nmea.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <numbers>
#include <stdexcept>

namespace gearpulse::sim {
namespace {

constexpr double kMetersPerKnot = 1852.0 / 3600.0;  // 1 kn = 1 NM/h, 1 NM = 1852 m (exact)
constexpr double kEarthRadius = 6371008.8;          // m, mean radius; the track only needs to be plausible

std::string format(const char* fmt, auto... args) {
  char buf[160];
  const int n = std::snprintf(buf, sizeof buf, fmt, args...);
  return std::string(buf, static_cast<std::size_t>(std::max(0, std::min<int>(n, sizeof buf - 1))));
}

// ddmm.mmmmm / dddmm.mmmmm with hemisphere letter.
std::string nmea_coord(double deg, bool latitude) {
  const char hemi = latitude ? (deg >= 0 ? 'N' : 'S') : (deg >= 0 ? 'E' : 'W');
  double a = std::fabs(deg);
  int whole = static_cast<int>(a);
  double minutes = (a - whole) * 60.0;
  if (minutes >= 59.999995) {  // keep the rounded field below 60
    minutes = 0.0;
    ++whole;
  }
  return latitude ? format("%02d%08.5f,%c", whole, minutes, hemi)
                  : format("%03d%08.5f,%c", whole, minutes, hemi);
}

struct Utc {
  int h, m;
  double s;
};
// To the hundredth of a second the sentences print: an epoch a tenth of a second before a whole second
// (59.9 s as 59.899999...) never prints as 60.00 of the minute before.
Utc utc_of(double seconds_of_day) {
  const long long centis = std::llround(seconds_of_day * 100.0) % (86400LL * 100);
  const int whole = static_cast<int>(centis / 100);
  return {whole / 3600, (whole / 60) % 60, static_cast<double>(centis - (whole / 60) * 6000LL) / 100.0};
}

}  // namespace

std::string nmea_sentence(std::string_view body) {
  unsigned sum = 0;
  for (const char c : body)
    sum ^= static_cast<unsigned char>(c);
  std::string sentence;
  sentence.reserve(body.size() + 6);
  sentence += '$';
  sentence += body;
  sentence += format("*%02X\r\n", sum & 0xFFu);
  return sentence;
}

std::vector<std::string> make_nmea_log(std::span<const NmeaEpoch> epochs, const NmeaTrack& track) {
  std::vector<std::string> out;
  out.reserve(epochs.size() * 2);
  const double heading = track.heading_deg * std::numbers::pi / 180.0;
  double lat = track.lat0_deg;
  double lon = track.lon0_deg;
  double prev_t = epochs.empty() ? 0.0 : epochs.front().t;
  double prev_speed = std::numeric_limits<double>::quiet_NaN();
  for (const NmeaEpoch& e : epochs) {
    const bool fix = std::isfinite(e.speed);
    if (fix && std::isfinite(prev_speed)) {
      const double dist = 0.5 * (prev_speed + e.speed) * (e.t - prev_t);
      lat += dist * std::cos(heading) / kEarthRadius * 180.0 / std::numbers::pi;
      lon += dist * std::sin(heading) / (kEarthRadius * std::cos(lat * std::numbers::pi / 180.0)) * 180.0 /
             std::numbers::pi;
    }
    prev_t = e.t;
    prev_speed = e.speed;

    const Utc u = utc_of(track.utc_seconds_of_day + e.t);
    const std::string hms = format("%02d%02d%05.2f", u.h, u.m, u.s);
    const std::string date = format("%02d%02d%02d", track.day, track.month, track.year % 100);
    // RMC first, as u-blox receivers send it: gpsd then reports the epoch with RMC's speed, and the GGA
    // that follows only adds altitude and fix quality to the same fix.
    if (fix) {
      out.push_back(nmea_sentence("GPRMC," + hms + ",A," + nmea_coord(lat, true) + "," +
                                  nmea_coord(lon, false) +
                                  format(",%.3f,%.1f,", std::max(0.0, e.speed) / kMetersPerKnot,
                                         std::fmod(track.heading_deg + 360.0, 360.0)) +
                                  date + ",,,A"));
      out.push_back(nmea_sentence("GPGGA," + hms + "," + nmea_coord(lat, true) + "," +
                                  nmea_coord(lon, false) +
                                  format(",1,08,0.9,%.1f,M,40.0,M,,", track.altitude_m)));
    } else {
      out.push_back(nmea_sentence("GPRMC," + hms + ",V,,,,,,," + date + ",,,N"));
      out.push_back(nmea_sentence("GPGGA," + hms + ",,,,,0,00,99.99,,,,,,"));
    }
  }
  return out;
}

void write_nmea_log(const std::filesystem::path& path, std::span<const NmeaEpoch> epochs,
                    const NmeaTrack& track) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (!f) throw std::runtime_error(path.string() + ": cannot create NMEA log");
  for (const std::string& line : make_nmea_log(epochs, track))
    f << line;
  f.flush();
  if (!f) throw std::runtime_error(path.string() + ": write failed");
}

std::vector<NmeaEpoch> epochs_at_1hz(std::span<const double> speeds) {
  std::vector<NmeaEpoch> out;
  out.reserve(speeds.size());
  for (std::size_t i = 0; i < speeds.size(); ++i)
    out.push_back({static_cast<double>(i), speeds[i]});
  return out;
}

}  // namespace gearpulse::sim
