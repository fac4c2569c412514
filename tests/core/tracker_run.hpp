#pragma once
// What the tracker's test files (tracker_test.cpp, tracker_clean_test.cpp, tracker_noise_test.cpp,
// tracker_scenes_test.cpp) share: a signal fed in blocks as a capture thread does, the track's accuracy
// against the true line, and the default configuration at a sample rate.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <span>
#include <vector>

#include "core/sliding_dft_tracker.hpp"
#include "tools/sim/lighter_signal.hpp"

namespace gearpulse::test::tracker_run {

// Feeds `x` in blocks of `block` frames (like a capture thread) and collects every output.
inline std::vector<TrackPoint> track(SlidingDftTracker& tracker, const std::vector<float>& x,
                                     std::size_t block = 1024) {
  std::vector<TrackPoint> out;
  for (std::size_t at = 0; at < x.size(); at += block) {
    tracker.push(std::span<const float>(x).subspan(at, std::min(block, x.size() - at)));
    TrackPoint p;
    while (tracker.pop(p))
      out.push_back(p);
  }
  return out;
}

struct Stats {
  double rmse = 0.0;
  double max_error = 0.0;
  double tracked_fraction = 0.0;
  std::size_t considered = 0;
};

// Accuracy against the truth over hops with centre in [from, to].
inline Stats score(const std::vector<TrackPoint>& points, const sim::FrequencyTrajectory& truth, double from,
                   double to) {
  Stats s;
  double sq = 0.0;
  std::size_t tracked = 0;
  for (const TrackPoint& p : points) {
    if (p.t < from || p.t > to) continue;
    ++s.considered;
    if (!p.tracked) continue;
    ++tracked;
    const double e = p.freq - truth(p.t);
    sq += e * e;
    s.max_error = std::max(s.max_error, std::abs(e));
  }
  s.rmse = tracked ? std::sqrt(sq / static_cast<double>(tracked)) : NAN;
  s.tracked_fraction = s.considered ? static_cast<double>(tracked) / static_cast<double>(s.considered) : 0.0;
  return s;
}

inline double tracked_fraction(const std::vector<TrackPoint>& points) {
  if (points.empty()) return 0.0;
  const auto n = std::count_if(points.begin(), points.end(), [](const TrackPoint& p) { return p.tracked; });
  return static_cast<double>(n) / static_cast<double>(points.size());
}

inline TrackerConfig config_at(double fs) {
  TrackerConfig c;
  c.sample_rate_hz = fs;
  return c;
}

}  // namespace gearpulse::test::tracker_run
