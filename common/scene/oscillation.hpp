// Sustained-oscillation detection on a sampled signal (the simulator's verdict, compared
// with the analyser's).
#pragma once

#include <span>

namespace teleop::scene {

struct Oscillation {
  bool detected{false};
  double amplitude_m{0.0};           // half the peak-to-peak of the last window about its mean
  double frequency_hz{0.0};          // from the band crossings of the last window
  double previous_amplitude_m{0.0};  // the window before it
};

// Looks at the last `window_s` of `x` (sampled every `period_s`) and the window before it, each
// about its least-squares line: a sustained oscillation has at least `min_amplitude_m` and two
// full cycles in the last window (swings across a band of half `min_amplitude_m`, so encoder
// dither is none), is still swinging at the window's end (its last swing within two half
// periods), its peak-to-peak trend over the window's cycles loses less than 3/4 per window (a
// ringing step response is no buzz), and it has not decayed to less than half of the
// previous window's amplitude.
[[nodiscard]] Oscillation detect_oscillation(std::span<const double> x, double period_s,
                                             double window_s, double min_amplitude_m = 1e-5);

}  // namespace teleop::scene
