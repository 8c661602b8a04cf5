// The simulator-analyser agreement campaign of test_scene, with the non-idealities on as well
// (encoder quantisation, load-cell noise, friction, actuator saturation): how the picture
// changes. Prints a table.
//
//   build/bench/bench_agreement [cases]
#include <fmt/format.h>

#include <cstdlib>
#include <random>

#include "tests/unit/scene/agreement.hpp"

int main(int argc, char** argv) {
  using namespace teleop::scene::testing;
  const int cases = argc > 1 ? std::atoi(argv[1]) : 200;
  fmt::print(
      "| sensors | predicted | cases | settled (< 1 um) | small cycle (not sustained) | "
      "sustained oscillation |\n|---|---|---|---|---|---|\n");
  for (const bool ideal : {true, false}) {
    // Same seed: the same teleoperators in both runs.
    std::mt19937 rng(20261121);
    int n[3] = {0, 0, 0};
    int settled[3] = {0, 0, 0};
    int small[3] = {0, 0, 0};
    int sustained[3] = {0, 0, 0};
    for (int i = 0; i < cases; ++i) {
      const Case c = random_case(rng, ideal);
      const Outcome o = run_case(c);
      const int k = c.min_damping_ratio > 0.02 ? 0 : c.min_damping_ratio < -0.02 ? 2 : 1;
      ++n[k];
      if (o.sustained) {
        ++sustained[k];
      } else if (o.settled) {
        ++settled[k];
      } else {
        ++small[k];
      }
    }
    const char* names[3] = {"zeta > 0.02", "within +-0.02", "zeta < -0.02"};
    for (int k = 0; k < 3; ++k) {
      fmt::print("| {} | {} | {} | {} | {} | {} |\n", ideal ? "ideal" : "paper hardware", names[k],
                 n[k], settled[k], small[k], sustained[k]);
    }
  }
  return 0;
}
