#include "common/scene/oscillation.hpp"

#include <algorithm>
#include <cmath>

namespace teleop::scene {

namespace {

struct WindowStats {
  double amplitude{0.0};
  double frequency_hz{0.0};
};

WindowStats stats(std::span<const double> w, double period_s) {
  WindowStats out;
  if (w.empty()) return out;
  double mean = 0.0;
  for (const double v : w) mean += v;
  mean /= static_cast<double>(w.size());
  const auto [lo, hi] = std::minmax_element(w.begin(), w.end());
  out.amplitude = 0.5 * (*hi - *lo);
  int crossings = 0;
  for (std::size_t i = 1; i < w.size(); ++i) {
    if ((w[i - 1] - mean) * (w[i] - mean) < 0.0) ++crossings;
  }
  const double span_s = static_cast<double>(w.size()) * period_s;
  out.frequency_hz = span_s > 0.0 ? 0.5 * crossings / span_s : 0.0;
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
  out.detected = last.amplitude >= min_amplitude_m && last.amplitude >= 0.5 * previous.amplitude;
  return out;
}

}  // namespace teleop::scene
