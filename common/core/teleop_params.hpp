// Plain domain structs describing one teleoperator (docs/architecture.md §2). No protobuf, no I/O:
// the configuration loader fills these, the stability engine, control law and simulator read them.
#pragma once

#include <vector>

#include "common/core/defaults.hpp"

namespace teleop {

// A mass-damper device as felt at the handle, along its arc (eq. 5-6 of Abbott-Okamura).
struct DeviceParams {
  double mass_kg{0.0};
  double damping_Ns_per_m{0.0};
};

// Unilateral virtual wall (eq. 7): acts for x > position_m with the given stiffness.
struct FixtureParams {
  double stiffness_N_per_m{0.0};
  double position_m{0.0};
};

// Three-channel law gains (eqs. 8-9), SI units: kp* in N/m, kd*/kv* in Ns/m, kfm dimensionless.
struct Gains {
  double kpm{0.0};
  double kps{0.0};
  double kdm{0.0};
  double kds{0.0};
  double kvm{0.0};
  double kvs{0.0};
  double kfm{0.0};
  [[nodiscard]] bool operator==(const Gains&) const = default;
};

// Slave follows position * x_m; master feels force * (...). Both 1 in the paper.
struct Scaling {
  double position{1.0};
  double force{1.0};
};

// A human finger (or hand) as an LTI mass-spring-damper (eq. 2).
struct HumanImpedance {
  double mass_kg{0.0};
  double damping_Ns_per_m{0.0};
  double stiffness_N_per_m{0.0};
};

// value(F) = intercept + slope_per_N * F, a bounding line of Fig. 4.
struct LinearBound {
  double intercept{0.0};
  double slope_per_N{0.0};
  [[nodiscard]] double at(double force_N) const { return intercept + slope_per_N * force_N; }
};

struct ParameterBand {
  LinearBound lower{};
  LinearBound upper{};
};

// Human parameters bounded by lines against grip force, sampled on a grid (Fig. 5).
struct HumanBand {
  std::vector<double> force_levels_N{};
  int points_per_axis{defaults::kBandPointsPerAxis};
  ParameterBand mass_kg{};
  ParameterBand damping_Ns_per_m{};
  ParameterBand stiffness_N_per_m{};
};

enum class HumanKind { kNone, kFixed, kBand };

struct HumanModel {
  HumanKind kind{HumanKind::kBand};
  HumanImpedance fixed{};
  HumanBand band{};
};

// The default band when a configuration names none. An assumption, not measured data: the
// paper's finger data (Hajian & Howe 1997) is plotted in its Fig. 4 but not tabulated.
[[nodiscard]] HumanBand default_human_band();

// Vlachos-Papadopoulos force-controlled haptic device rendering a virtual spring-damper.
struct ForceLoopParams {
  double mass_kg{0.0};
  double damping_Ns_per_m{0.0};
  double kp{0.0};
  double ki{0.0};
  double sample_rate_hz{0.0};
  double environment_stiffness_N_per_m{0.0};
  double environment_damping_Ns_per_m{0.0};
  int sensor_average_samples{defaults::kSensorAverageSamples};
};

struct AnalysisSettings {
  double required_damping_ratio{0.0};
  double stiffness_tolerance_N_per_m{defaults::kStiffnessTolerance_N_per_m};
};

// Everything the stability engine needs about a bilateral teleoperator.
struct TeleopParams {
  double sample_rate_hz{0.0};
  DeviceParams master_device{};
  DeviceParams slave_device{};
  FixtureParams master_fixture{};
  FixtureParams slave_fixture{};
  Gains gains{};
  Scaling scaling{};
  double velocity_cutoff_hz{0.0};  // 0: plain backward difference
  int round_trip_delay_samples{0};
  HumanModel human{};
  AnalysisSettings analysis{};

  [[nodiscard]] double period_s() const { return 1.0 / sample_rate_hz; }
};

}  // namespace teleop
