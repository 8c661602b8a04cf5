// examples/cartesian3.textproto's teleoperator for the live three-axis tests (test_nodes_axes,
// test_launch_axes): the same devices, planes, gains and filter, with the fixed human of
// examples/scenes/cartesian3_planes.textproto, the nodes on this test's ports.
#pragma once

#include <string>

#include "tests/integration/node_harness.hpp"

namespace teleop::test {

// `scene`: the scene section (the human's push); `extra`: further sections (link, supervisor,
// security).
inline std::string cartesian3_system(const Ports& p, const std::string& scene,
                                     const std::string& extra) {
  return "sample_rate_hz: 1000\n"
         "axes: 3\n"
         "master { device { mass_matrix_kg: [0.05, 0.005, 0, 0.005, 0.05, 0, 0, 0, 0.06] "
         "damping_Ns_per_m_per_axis: [0.4, 0.4, 0.5] kinematics { cartesian {} } } " +
         node_section(p, true) +
         " }\n"
         "slave { device { mass_matrix_kg: [0.04, 0.04, 0.045] damping_Ns_per_m: 0.5 } "
         "fixture { plane { normal: [0, 0, -1] offset_m: 0.01 stiffness_N_per_m: 1500 } "
         "plane { normal: [1, 1, 0] offset_m: 0.02 stiffness_N_per_m: 1000 } } " +
         node_section(p, false) +
         " }\n"
         "gains { kpm: 600 kps: 600 kdm_per_axis: [2, 2, 2.5] "
         "kds_matrix: [2, 0, 0, 0, 2, 0, 0, 0, 2.5] }\n"
         "velocity_filter { cutoff_hz: 200 }\n"
         "human { fixed { mass_kg: 0.012 damping_Ns_per_m: 0.76 stiffness_N_per_m: 70 } }\n" +
         scene + "\n" + extra;
}

}  // namespace teleop::test
