// A scene as plain structs: what `teleopctl simulate` plays (the configuration loader fills it
// from a SystemConfig with a `scene` section).
#pragma once

#include <cstdint>
#include <optional>

#include "common/control/force_loop_controller.hpp"
#include "common/control/law_params.hpp"
#include "common/core/teleop_params.hpp"
#include "common/device/sim_device.hpp"

namespace teleop::scene {

// The Vlachos-Papadopoulos device moved by a hand through a stiff grip (the hand is the
// device's "human": its impedance is the grip, its exogenous force k x_h + b x_h').
struct ForceDeviceSetup {
  device::SimDeviceConfig device{};
  control::ForceLoopSettings controller{};
  control::VirtualSpringDamper environment{};  // the virtual tissue rendered
  // Hand trajectory for reporting the tracking of the device (position_m(t)).
  sim::ForceProfile hand_position_m{};
};

struct SceneSetup {
  double duration_s{1.0};
  std::uint64_t seed{0};
  bool ideal{false};
  double output_rate_hz{0.0};  // 0: every sample
  // Bilateral paddles.
  TeleopParams teleop{};
  control::LawParams law{};
  device::SimDeviceConfig master{};
  device::SimDeviceConfig slave{};
  // Start at the static equilibrium of this constant push with the slave displaced by the
  // perturbation, instead of at rest at 0.
  std::optional<double> equilibrium_perturbation_m{};
  double equilibrium_push_N{0.0};
  // Force-controlled device scenes (then the bilateral fields are unused).
  std::optional<ForceDeviceSetup> force_device{};
};

}  // namespace teleop::scene
