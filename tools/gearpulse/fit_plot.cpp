#include "tools/gearpulse/fit_plot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

namespace gearpulse::cli {
namespace {

constexpr int kBins = 200;  // as Fig. 1
constexpr double kWidth = 960, kHeight = 480;
constexpr double kLeft = 70, kRight = 20, kTop = 40, kBottom = 50;
constexpr std::size_t kDensitySamples = 20000;  // the overlay is averaged over at most this many samples

std::string fmt(const char* format, double a, double b = 0, double c = 0, double d = 0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, format, a, b, c, d);
  return buf;
}

double nice_step(double range, int target) {
  const double raw = range / target;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0})
    if (raw <= m * mag) return m * mag;
  return 10.0 * mag;
}

}  // namespace

std::string ratio_histogram_svg(std::span<const Sample> samples, const GearModel& model) {
  // The samples the estimator weighs: moving (speed above 2 sigma_v, as section 5 drops the rest), engine
  // tracked.
  const double min_speed = std::max(2.0 * model.sigma_speed, 0.5);
  std::vector<double> ratio;
  std::vector<const Sample*> used;
  double v_max = 0.0;
  for (const Sample& s : samples) {
    if (!s.has_speed() || !s.has_freq() || s.freq <= 0.0 || s.speed < min_speed) continue;
    ratio.push_back(s.speed / s.freq);
    used.push_back(&s);
    v_max = std::max(v_max, s.speed);
  }
  std::vector<double> sorted = ratio;
  std::sort(sorted.begin(), sorted.end());
  double hi =
      sorted.empty() ? 1.0 : sorted[static_cast<std::size_t>(0.99 * static_cast<double>(sorted.size() - 1))];
  for (const Gear& g : model.gears)
    hi = std::max(hi, 1.25 * g.theta);
  if (!(hi > 0.0)) hi = 1.0;
  const double bin = hi / kBins;

  std::vector<double> counts(kBins, 0.0);
  for (double r : ratio) {
    const int b = static_cast<int>(r / bin);
    if (b >= 0 && b < kBins) counts[static_cast<std::size_t>(b)] += 1.0;
  }

  // Expected counts per bin under the fitted eq. (6): for a sample with frequency f the ratio r = v/f has
  // density f * p(v = r f | f). The clutch-out part g() is the estimator's own histogram density when the
  // model carries one (extra.clutch_out), else uniform over the speed range as in the paper (section 5).
  // The curve is scaled to the number of plotted samples (the standstill spike lies below the cut).
  std::vector<double> g_density;
  double g_lo = 0.0, g_hi = v_max, beta = model.outlier_weight;
  if (const auto it = model.extra.find("clutch_out"); it != model.extra.end() && it->is_object()) {
    const auto& c = *it;
    if (c.contains("density") && c["density"].is_array() && c.contains("lo") && c.contains("hi") &&
        c["lo"].is_number() && c["hi"].is_number()) {
      for (const auto& d : c["density"])
        g_density.push_back(d.is_number() ? std::max(d.get<double>(), 0.0) : 0.0);
      g_lo = c["lo"].get<double>();
      g_hi = c["hi"].get<double>();
    }
    if (c.contains("weight") && c["weight"].is_number()) beta = c["weight"].get<double>();
  }
  const auto g = [&](double v) {
    if (!(v >= g_lo && v < g_hi)) return 0.0;
    if (g_density.empty()) return 1.0 / (g_hi - g_lo);
    const auto i =
        static_cast<std::size_t>((v - g_lo) / (g_hi - g_lo) * static_cast<double>(g_density.size()));
    return g_density[std::min(i, g_density.size() - 1)];
  };
  double alpha_sum = 0.0;
  for (const Gear& gear : model.gears)
    alpha_sum += gear.weight;
  const double n_gears = static_cast<double>(model.gears.size());
  if (model.gears.empty()) beta = 1.0;
  std::vector<double> total(kBins, 0.0), outlier(kBins, 0.0);
  const std::size_t stride = std::max<std::size_t>(1, used.size() / kDensitySamples);
  for (std::size_t k = 0; k < used.size(); k += stride) {
    const double f = used[k]->freq;
    for (int b = 0; b < kBins; ++b) {
      const double v = (b + 0.5) * bin * f;
      double p = 0.0;
      for (const Gear& gear : model.gears) {
        const double alpha = alpha_sum > 0.0 ? gear.weight : (1.0 - beta) / n_gears;
        const double var = std::max(gear.theta * gear.theta * model.sigma_freq * model.sigma_freq +
                                        model.sigma_speed * model.sigma_speed,
                                    1e-6);
        p += alpha * std::exp(-0.5 * (v - gear.theta * f) * (v - gear.theta * f) / var) /
             std::sqrt(2.0 * std::numbers::pi * var);
      }
      const double out = beta * g(v);
      total[static_cast<std::size_t>(b)] += (p + out) * f;
      outlier[static_cast<std::size_t>(b)] += out * f;
    }
  }
  double in_range = 0.0, mass = 0.0;
  for (int b = 0; b < kBins; ++b) {
    in_range += counts[static_cast<std::size_t>(b)];
    mass += total[static_cast<std::size_t>(b)];
  }
  const double scale = mass > 0.0 ? in_range / mass : 0.0;
  double y_max = 1.0;
  for (int b = 0; b < kBins; ++b) {
    total[static_cast<std::size_t>(b)] *= scale;
    outlier[static_cast<std::size_t>(b)] *= scale;
    y_max = std::max({y_max, counts[static_cast<std::size_t>(b)], total[static_cast<std::size_t>(b)]});
  }
  y_max *= 1.08;

  const double pw = kWidth - kLeft - kRight, ph = kHeight - kTop - kBottom;
  const auto px = [&](double r) { return kLeft + r / hi * pw; };
  const auto py = [&](double c) { return kTop + ph - c / y_max * ph; };

  std::string svg = fmt(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%.0f\" height=\"%.0f\" viewBox=\"0 0 %.0f %.0f\" "
      "font-family=\"sans-serif\" font-size=\"12\">\n",
      kWidth, kHeight, kWidth, kHeight);
  svg += "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  svg += fmt(
      "<text x=\"%.0f\" y=\"22\" font-size=\"15\">Histogram of speed / frequency: %.0f samples, %.0f gears",
      kLeft, static_cast<double>(ratio.size()), n_gears);
  svg += model.gears.empty() ? " (no gear ladder)</text>\n" : "</text>\n";
  // Histogram bars.
  svg += "<g fill=\"#9db4d0\" stroke=\"none\">\n";
  for (int b = 0; b < kBins; ++b) {
    const double c = counts[static_cast<std::size_t>(b)];
    if (c <= 0.0) continue;
    svg += fmt("<rect x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" height=\"%.2f\"/>\n", px(b * bin), py(c),
               std::max(pw / kBins - 0.3, 0.5), kTop + ph - py(c));
  }
  svg += "</g>\n";
  // Axes and ticks.
  svg += fmt("<path d=\"M%.1f %.1f V%.1f H%.1f\" stroke=\"black\" fill=\"none\"/>\n", kLeft, kTop, kTop + ph,
             kLeft + pw);
  const double xs = nice_step(hi, 10);
  for (double x = 0.0; x <= hi + 1e-12; x += xs) {
    svg += fmt("<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"black\"/>", px(x), kTop + ph,
               px(x), kTop + ph + 5);
    svg += fmt("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">%g</text>\n", px(x), kTop + ph + 18, x);
  }
  const double ys = nice_step(y_max, 6);
  for (double y = 0.0; y <= y_max; y += ys) {
    svg += fmt("<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"black\"/>", kLeft - 5, py(y),
               kLeft, py(y));
    svg += fmt("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\">%g</text>\n", kLeft - 8, py(y) + 4, y);
  }
  svg += fmt("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">speed / frequency, (m/s)/Hz</text>\n",
             kLeft + pw / 2, kHeight - 10);
  svg +=
      fmt("<text x=\"16\" y=\"%.1f\" transform=\"rotate(-90 16 %.1f)\" text-anchor=\"middle\">samples per "
          "bin</text>\n",
          kTop + ph / 2, kTop + ph / 2);
  // Fitted gear lines.
  for (std::size_t i = 0; i < model.gears.size(); ++i) {
    const double x = px(model.gears[i].theta);
    svg +=
        fmt("<line x1=\"%.2f\" y1=\"%.1f\" x2=\"%.2f\" y2=\"%.1f\" stroke=\"#1f4e9c\" stroke-width=\"1.5\"/>",
            x, kTop, x, kTop + ph);
    svg +=
        fmt("<text x=\"%.2f\" y=\"%.1f\" fill=\"#1f4e9c\" text-anchor=\"middle\">%.0f: %.4f</text>\n", x,
            kTop + 12 + 13.0 * static_cast<double>(i % 2), static_cast<double>(i + 1), model.gears[i].theta);
  }
  // Fitted densities.
  const auto polyline = [&](const std::vector<double>& y, const char* style) {
    std::string s = "<polyline fill=\"none\" " + std::string(style) + " points=\"";
    for (int b = 0; b < kBins; ++b)
      s += fmt("%.2f,%.2f ", px((b + 0.5) * bin), py(y[static_cast<std::size_t>(b)]));
    return s + "\"/>\n";
  };
  if (!used.empty()) {
    svg += polyline(total, "stroke=\"#c0392b\" stroke-width=\"1.5\"");
    svg += polyline(outlier, "stroke=\"#555\" stroke-dasharray=\"5,4\"");
  }
  // Legend.
  const double lx = kLeft + pw - 250, ly = kTop + 10;
  svg += fmt("<rect x=\"%.1f\" y=\"%.1f\" width=\"12\" height=\"10\" fill=\"#9db4d0\"/>", lx, ly);
  svg += fmt("<text x=\"%.1f\" y=\"%.1f\">samples (%.0f bins)</text>\n", lx + 18, ly + 10, kBins);
  svg +=
      fmt("<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#c0392b\" stroke-width=\"1.5\"/>",
          lx, ly + 21, lx + 12, ly + 21);
  svg += fmt("<text x=\"%.1f\" y=\"%.1f\">fitted mixture, eq. (6)</text>\n", lx + 18, ly + 25);
  svg +=
      fmt("<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#555\" stroke-dasharray=\"5,4\"/>",
          lx, ly + 36, lx + 12, ly + 36);
  svg += fmt("<text x=\"%.1f\" y=\"%.1f\">clutch-out / outlier part (beta g)</text>\n", lx + 18, ly + 40);
  svg +=
      fmt("<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#1f4e9c\" stroke-width=\"1.5\"/>",
          lx, ly + 51, lx + 12, ly + 51);
  svg += fmt("<text x=\"%.1f\" y=\"%.1f\">fitted theta per gear</text>\n", lx + 18, ly + 55);
  svg += "</svg>\n";
  return svg;
}

}  // namespace gearpulse::cli
