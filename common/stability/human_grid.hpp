// The humans a stability analysis must consider (Fig. 5): one, none, or a band on a grid.
#pragma once

#include <vector>

#include "common/core/teleop_params.hpp"

namespace teleop::stability {

struct HumanSample {
  bool has_force{false};  // a band sample carries the grip force it was drawn at
  double force_N{0.0};
  HumanImpedance impedance{};
};

// kNone -> one zero impedance; kFixed -> the one human; kBand -> at every force level,
// points_per_axis values of mass, damping and stiffness from lower to upper bound inclusive.
[[nodiscard]] std::vector<HumanSample> human_samples(const HumanModel& model);

}  // namespace teleop::stability
