#include "common/scene/oscillation.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace teleop::scene {

namespace {

struct WindowStats {
  double amplitude{0.0};
  double frequency_hz{0.0};
  int crossings{0};
  // The swing is still going at the window's end and its envelope has not decayed faster
  // than to half per window (see detect_oscillation).
  bool sustained{false};
};

// Half the peak-to-peak about the window's least-squares line (so a drift is no oscillation),
// and the crossings of a band of half-width `band_m` about that line (not about the middle of
// the range: a growing oscillation's range is its last swing): a swing counts only when it
// goes from one side of the band to the other, so a count of encoder dither on a bend of the
// trajectory (the residual of a ramp that slows on contact) is no crossing.
WindowStats stats(std::span<const double> w, double period_s, double window_s, double band_m) {
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
  auto residual = [&](std::size_t i) {
    return w[i] - mean - slope * (static_cast<double>(i) - tmean);
  };
  double lo = 0.0;
  double hi = 0.0;
  for (std::size_t i = 0; i < w.size(); ++i) {
    lo = std::min(lo, residual(i));
    hi = std::max(hi, residual(i));
  }
  out.amplitude = 0.5 * (hi - lo);

  // Crossings of the band, and the extreme of each half cycle between two of them.
  int side = 0;
  double extreme = 0.0;
  std::vector<std::size_t> at;      // sample of each crossing
  std::vector<double> half_cycles;  // |extreme| of each half cycle bounded by two crossings
  for (std::size_t i = 0; i < w.size(); ++i) {
    const double d = residual(i);
    const int now = d > band_m ? 1 : (d < -band_m ? -1 : 0);
    if (now != 0 && now != side) {
      if (side != 0) {
        if (!at.empty()) half_cycles.push_back(extreme);
        at.push_back(i);
      }
      side = now;
      extreme = 0.0;
    }
    if (side != 0 && d * side > extreme) extreme = d * side;
  }
  out.crossings = static_cast<int>(at.size());
  out.frequency_hz = 0.5 * out.crossings / (n * period_s);
  if (at.size() < 4) return out;

  // Still going: the last crossing no further from the end than two half periods (the
  // median spacing of the crossings).
  std::vector<std::size_t> gaps;
  for (std::size_t j = 1; j < at.size(); ++j) gaps.push_back(at[j] - at[j - 1]);
  std::nth_element(gaps.begin(), gaps.begin() + static_cast<std::ptrdiff_t>(gaps.size() / 2),
                   gaps.end());
  const auto spacing = static_cast<double>(gaps[gaps.size() / 2]);
  const bool going = static_cast<double>(w.size() - 1 - at.back()) <= 2.0 * spacing + 1.0;
  // Not decaying: the least-squares trend of log(peak to peak) over the cycles (each two
  // consecutive half cycles, one band width added for quantisation) loses less than
  // kDecayPerWindow per window. A trend over all the cycles, so that an irregular limit cycle
  // (a saturating or chattering one) is sustained; a ringing transient is not (a damping ratio
  // of 0.1 at 27 Hz decays by exp(-0.1 2 pi 27 0.5) = 2e-4 per 0.5 s window).
  constexpr double kDecayPerWindow = 0.25;
  double st = 0.0;
  double sl = 0.0;
  const std::size_t pairs = half_cycles.size() - 1;
  std::vector<double> t(pairs);
  std::vector<double> l(pairs);
  for (std::size_t j = 0; j < pairs; ++j) {
    t[j] = static_cast<double>(at[j + 1]) * period_s;
    l[j] = std::log(half_cycles[j] + half_cycles[j + 1] + 2.0 * band_m);
    st += t[j];
    sl += l[j];
  }
  st /= static_cast<double>(pairs);
  sl /= static_cast<double>(pairs);
  double stt = 0.0;
  double stl = 0.0;
  for (std::size_t j = 0; j < pairs; ++j) {
    stt += (t[j] - st) * (t[j] - st);
    stl += (t[j] - st) * (l[j] - sl);
  }
  const double rate_per_s = stt > 0.0 ? stl / stt : 0.0;
  out.sustained = going && rate_per_s * window_s >= std::log(kDecayPerWindow);
  return out;
}

}  // namespace

Oscillation detect_oscillation(std::span<const double> x, double period_s, double window_s,
                               double min_amplitude_m) {
  Oscillation out;
  const auto n = static_cast<std::size_t>(std::max(1.0, std::round(window_s / period_s)));
  if (x.size() < 2 * n) return out;
  const double band_m = 0.5 * min_amplitude_m;
  const WindowStats last = stats(x.subspan(x.size() - n, n), period_s, window_s, band_m);
  const WindowStats previous = stats(x.subspan(x.size() - 2 * n, n), period_s, window_s, band_m);
  out.amplitude_m = last.amplitude;
  out.previous_amplitude_m = previous.amplitude;
  out.frequency_hz = last.frequency_hz;
  // At least two full cycles in the window: a slow swing driven by the operator is no buzz.
  out.detected = last.amplitude >= min_amplitude_m && last.crossings >= 4 && last.sustained &&
                 last.amplitude >= 0.5 * previous.amplitude;
  return out;
}

}  // namespace teleop::scene
