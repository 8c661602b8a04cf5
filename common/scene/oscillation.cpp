#include "common/scene/oscillation.hpp"

#include <algorithm>
#include <cmath>

namespace teleop::scene {

namespace {

struct WindowStats {
  double amplitude{0.0};
  double frequency_hz{0.0};
  int crossings{0};
};

// Half the peak-to-peak about the window's least-squares line (so a drift is no oscillation),
// and the frequency from the crossings of that line.
WindowStats stats(std::span<const double> w, double period_s) {
  WindowStats out;
  const auto n = static_cast<double>(w.size());
  if (w.size() < 2) return out;
  double mean = 0.0;
  double tmean = 0.5 * (n - 1.0);
  for (const double v : w) mean += v;
  mean /= n;
  double sxy = 0.0;
  double sxx = 0.0;
  for (std::size_t i = 0; i < w.size(); ++i) {
    const double t = static_cast<double>(i) - tmean;
    sxy += t * (w[i] - mean);
    sxx += t * t;
  }
  const double slope = sxy / sxx;
  double lo = 0.0;
  double hi = 0.0;
  double previous = 0.0;
  for (std::size_t i = 0; i < w.size(); ++i) {
    const double r = w[i] - mean - slope * (static_cast<double>(i) - tmean);
    lo = std::min(lo, r);
    hi = std::max(hi, r);
    if (i > 0 && previous * r < 0.0) ++out.crossings;
    previous = r;
  }
  out.amplitude = 0.5 * (hi - lo);
  out.frequency_hz = 0.5 * out.crossings / (n * period_s);
  return out;
}

}  // namespace

Oscillation detect_oscillation(std::span<const double> x, double period_s, double window_s,
                               double min_amplitude_m) {
  Oscillation out;
  const auto n = static_cast<std::size_t>(std::max(1.0, std::round(window_s / period_s)));
  if (x.size() < 2 * n) return out;
  const WindowStats last = stats(x.subspan(x.size() - n, n), period_s);
  const WindowStats previous = stats(x.subspan(x.size() - 2 * n, n), period_s);
  out.amplitude_m = last.amplitude;
  out.previous_amplitude_m = previous.amplitude;
  out.frequency_hz = last.frequency_hz;
  // At least two full cycles in the window: a slow swing driven by the operator is no buzz.
  out.detected = last.amplitude >= min_amplitude_m && last.crossings >= 4 &&
                 last.amplitude >= 0.5 * previous.amplitude;
  return out;
}

}  // namespace teleop::scene
