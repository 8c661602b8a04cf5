// Identification of a device's mass and damping from recorded motion (Abbott-Okamura §4.1,
// eqs. 32-35). The free device obeys
//   m x'' + b x' = F                                                        (eq. 32)
// with F the external force on it along +x (the load cell's F_h, plus any actuator force, minus
// the environment's F_e). Sampling it many times and stacking runs gives
//   [x'' x'] [m b]^T = F,   D p = F,   p = D^+ F                          (eqs. 33-35)
// with D^+ the SVD pseudoinverse.
//
// Derivatives, as the paper: the position is smoothed by a multiple-pass three-point moving
// average, differentiated, the velocity smoothed again and differentiated to the acceleration.
// Two choices the paper does not spell out, made so that smoothing cannot bias the fit:
//  - Differentiation is the five-point central difference (x[-2] - 8x[-1] + 8x[1] - x[2])/12T:
//    zero phase and fourth-order accurate. A two-point central difference scales the velocity by
//    sin(wT)/wT and the acceleration by its square, biasing m by about (wT)^2/3 (0.5 % at 20 Hz
//    and 1 kHz); this one by (wT)^4/15.
//  - The force is smoothed by the same 2 x passes moving averages as the regressors (x'' and x'
//    both carry them), so the fitted equation is eq. 32 through one common linear filter and
//    holds exactly for any passes and any frequency content. Only the noise differs.
// Each moving-average pass and each differentiation needs neighbours, so their edges are
// dropped (no padding): 2 passes + 4 samples at each end of a run, plus trim_samples.
// Alignment matters as much as smoothing: a force half a sample late biases the damping by
// m w^2 T / (2 b) (see Series::held_force_N).
//
// Plain data in, plain data out; no I/O. Not RT-safe: an offline tool.
#pragma once

#include <cstddef>
#include <vector>

namespace teleop::stability {

// One recorded run at a uniform sample rate.
struct Series {
  // Sample period, s. Used when time_s is empty.
  double period_s{0.0};
  // Sample times, s (optional): strictly increasing and uniform to 1 % of the mean step; the
  // period is the mean step. Overrides period_s.
  std::vector<double> time_s{};
  // Position along the device's arc, m (as sensed: encoder steps are what smoothing is for).
  std::vector<double> position_m{};
  // External force along +x sampled at the same instants as the position, N (a load cell).
  std::vector<double> force_N{};
  // Optional: a force held constant over the sample period ending at each sample (an actuator
  // command written after sample k-1 and applied until sample k), N, along +x. Its value at
  // sample k's instant is taken as the mean of the periods on either side, (h[k] + h[k+1])/2,
  // so the last sample of the run is dropped. Using it unshifted would delay the force by
  // half a sample and bias the damping by about m w^2 T / (2 b) (14 % at 10 Hz on the paddle).
  std::vector<double> held_force_N{};
};

struct IdentifyOptions {
  // Three-point moving-average passes, applied to the position before the first difference and
  // again to the velocity before the second (so 2 x passes on x'', x' and F). The whole
  // cascade's -3 dB point is near f_s sqrt(3 ln2 / (4 passes)) / (2 pi): 41 Hz for 8 passes at
  // 1 kHz, well above the 0.5-15 Hz a hand or a random push puts into a paddle (and the mass
  // shows above b/(2 pi m), about 2 Hz). Fewer passes keep more of the encoder staircase in
  // x'', and noise in a regressor biases its coefficient towards 0 (errors in variables): on
  // the simulated paddles (0.145 mm counts, a 0.5 N rms push) the mass comes out low by 36 %,
  // 3 %, 0.6 % and 0.1 % with 1, 4, 8 and 16 passes, the damping within 0.2 % throughout.
  // Scale the passes with the square of the sample rate to keep the same cut-off. >= 1.
  int smoothing_passes{8};
  // Further samples dropped at each end of each run, after the filters' own edges (a start-up
  // transient, a release at the end).
  std::size_t trim_samples{0};
  // false: fit the raw force, as the paper's text reads; only right when the force's content
  // is far below the smoothing's cut-off.
  bool smooth_force{true};
};

struct RunFit {
  std::size_t samples{0};  // rows this run contributed
  double r_squared{0.0};   // of the common parameters on this run alone
};

struct IdentifyResult {
  double mass_kg{0.0};
  double damping_Ns_per_m{0.0};
  // Coefficient of determination on the fitted (smoothed) force: 1 - SS_res / SS_tot, SS_tot
  // about the mean of all rows.
  double r_squared{0.0};
  double residual_rms_N{0.0};
  std::size_t samples{0};  // rows of D, all runs
  // Of D with unit-norm columns: 1 when x'' and x' are uncorrelated, large when they are
  // nearly proportional (a free decay) and the split between m and b is poorly determined.
  double condition_number{0.0};
  std::vector<RunFit> runs{};
};

// Throws std::invalid_argument naming the run and the problem: no runs, mismatched lengths, a
// non-finite value (with its index), a bad period or non-uniform times, too few samples for the
// smoothing and trimming, a run whose position or force is constant, or stacked data that
// cannot separate m from b.
[[nodiscard]] IdentifyResult identify(const std::vector<Series>& runs,
                                      const IdentifyOptions& options = {});

// The rows one run contributes to the fit: the smoothed acceleration and velocity (the
// regressors x'' and x') and the (smoothed) force of samples first_sample, first_sample + 1, ...
// of the run, for showing the measured force against the fitted m x'' + b x'. Throws as
// identify() does for this run.
struct RegressionRows {
  std::size_t first_sample{0};
  std::vector<double> acceleration{};
  std::vector<double> velocity{};
  std::vector<double> force{};
};
[[nodiscard]] RegressionRows regression_rows(const Series& run,
                                             const IdentifyOptions& options = {});

// Rows a run of `samples` samples contributes: all but 2 smoothing_passes + 4 + trim_samples at
// each end and, with a held force, the last sample; 0 when fewer than 3 would remain (an error
// in identify()).
[[nodiscard]] std::size_t usable_rows(std::size_t samples, bool has_held_force,
                                      const IdentifyOptions& options);

}  // namespace teleop::stability
