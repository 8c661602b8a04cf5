#include "common/core/teleop_params.hpp"

namespace teleop {

HumanBand default_human_band() {
  HumanBand band;
  band.force_levels_N = {2.0, 5.0, 8.0, 11.0, 14.0, 17.0, 20.0};
  band.points_per_axis = 4;
  band.mass_kg = {{0.003, 0.0}, {0.012, 0.0}};
  band.damping_Ns_per_m = {{0.6, 0.08}, {2.0, 0.25}};
  band.stiffness_N_per_m = {{50.0, 10.0}, {100.0, 45.0}};
  return band;
}

}  // namespace teleop
