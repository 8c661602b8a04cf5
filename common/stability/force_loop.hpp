// Stability of the Vlachos-Papadopoulos force loop (paper eqs. 13-17, Table II;
// docs/architecture.md §2.8):
//   1 + G_m G_v G_c H_s = 0,  G_m = 1/(M s^2 + B s),  G_v = K_v + B_v s,
//   G_c = K_p (P) or K_p + K_i/s (PI, when ki > 0),  H_s = (2 - T s)/(2 + T s),  T = 1/rate.
// The model is the paper's: the sensor average (sensor_average_samples) is not part of it.
#pragma once

#include <complex>
#include <optional>
#include <string>
#include <vector>

#include "common/core/teleop_params.hpp"
#include "common/stability/verdict.hpp"

namespace teleop::stability {

struct ForceLoopResult {
  // Largest B_v such that every B_v in [0, B_v] is stable at the configured K_v, K_p, K_i.
  // For P it is the larger root of eq. 15 solved for B_v, always below eq. 14's bound
  // (2M + B T)/(K_p T), which it approaches as K_v -> 0.
  std::optional<double> bv_limit_Ns_per_m{};
  // The paper's eq. 14, B_v < (2M + B T)/(K_p T): the s^2 coefficient of the loop (the same for
  // P and PI), necessary at any K_v; absent when K_p = 0.
  std::optional<double> bv_limit_eq14_Ns_per_m{};
  // Largest K_v such that every K_v in (0, K_v] is stable at the configured B_v, K_p, K_i.
  // For P it is eq. 15 (given eq. 14 holds); for PI a search to 1e-9 relative, up to 1e9.
  std::optional<double> kv_limit_N_per_m{};
  // Why a limit is absent; empty when both exist.
  std::string limit_reason{};
  // At the configured parameters: Routh-Hurwitz, cross-checked against the roots.
  Verdict verdict{Verdict::kUncertain};
  bool stable{false};  // verdict == kStable
  // Descending powers of s: cubic for P, quartic for PI.
  std::vector<double> characteristic_polynomial{};
  // Sorted by decreasing real part.
  std::vector<std::complex<double>> roots{};
  bool proportional_integral{false};
};

// Throws std::invalid_argument naming the field ("force_loop.mass_kg must be > 0, got -1").
void validate_force_loop_params(const ForceLoopParams& params);

// (M s^2 + B s)(2 + T s) [* s for PI] + G_c numerator * (K_v + B_v s)(2 - T s), descending.
// Validates first.
[[nodiscard]] std::vector<double> characteristic_polynomial(const ForceLoopParams& params);

// Validates first. Not RT-safe (allocates); an analysis-time function.
[[nodiscard]] ForceLoopResult analyze_force_loop(const ForceLoopParams& params);

}  // namespace teleop::stability
