// Run time against error for the human-grid resolution: the maximum stable stiffness found
// with points_per_axis = n on the default band, against a converged fine grid (finer in
// force and in every parameter), by the exact method (crossings) and by the old scan (x1.2,
// bisection, verified halvings). Prints the table docs/benchmarks.md quotes.
//
//   build/bench/bench_grid_error [--rates 500,1000]
#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "common/stability/stiffness_search.hpp"

namespace {

using namespace teleop;
using namespace teleop::stability;

// The shipped example (Figs. 7/11 gains, 200 Hz filter) and the Fig. 6 gains (unfiltered).
TeleopParams paddles(double rate_hz, bool fig6) {
  TeleopParams p;
  p.sample_rate_hz = rate_hz;
  p.master_device = {0.040, 0.41};
  p.slave_device = {0.036, 0.49};
  p.gains = fig6 ? Gains{800.0, 800.0, 6.0, 6.0, 0.0, 0.0, 0.0}
                 : Gains{600.0, 600.0, 2.0, 2.0, 0.0, 0.0, 0.0};
  p.velocity_cutoff_hz = fig6 ? 0.0 : 200.0;
  p.human.kind = HumanKind::kBand;
  p.human.band = default_human_band();
  p.analysis.stiffness_tolerance_N_per_m = 0.01;
  return p;
}

struct Timed {
  double limit{0.0};
  double ms{0.0};
};

Timed timed_limit(const TeleopParams& p, Side side, bool exact = true) {
  const auto t0 = std::chrono::steady_clock::now();
  const StiffnessLimit l =
      exact ? max_stable_stiffness(p, side) : max_stable_stiffness_scan(p, side);
  const auto t1 = std::chrono::steady_clock::now();
  return {l.max_stable_stiffness_N_per_m.value_or(std::nan("")),
          std::chrono::duration<double, std::milli>(t1 - t0).count()};
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<double> rates{500.0, 1000.0};
  if (argc == 3 && std::strcmp(argv[1], "--rates") == 0) {
    rates.clear();
    const std::string s = argv[2];
    std::size_t pos = 0;
    while (pos <= s.size()) {
      const std::size_t comma = s.find(',', pos);
      rates.push_back(std::stod(s.substr(pos, comma - pos)));
      if (comma == std::string::npos) break;
      pos = comma + 1;
    }
  }
  fmt::print(
      "| gains | rate (Hz) | side | points/axis | humans | exact (ms) | K_max (N/m) | "
      "error vs fine grid | old scan (ms) | old scan's error |\n");
  fmt::print("|---|---|---|---|---|---|---|---|---|---|\n");
  for (const bool fig6 : {false, true}) {
    const char* gains = fig6 ? "Fig. 6: 800/6, no filter" : "example: 600/2, 200 Hz";
    for (const double rate : rates) {
      for (const Side side : {Side::kSlave, Side::kMaster}) {
        TeleopParams fine = paddles(rate, fig6);
        fine.human.band.force_levels_N.clear();
        for (int f = 2; f <= 20; ++f) fine.human.band.force_levels_N.push_back(f);
        fine.human.band.points_per_axis = 12;
        const Timed ref = timed_limit(fine, side);
        const char* side_name = side == Side::kSlave ? "slave" : "master";
        for (const int n : {2, 3, 4, 6}) {
          TeleopParams p = paddles(rate, fig6);
          p.human.band.points_per_axis = n;
          const Timed t = timed_limit(p, side);
          const Timed old = timed_limit(p, side, false);
          const std::size_t humans =
              p.human.band.force_levels_N.size() * static_cast<std::size_t>(n * n * n);
          fmt::print(
              "| {} | {:g} | {} | {} | {} | {:.2f} | {:.2f} | {:+.3f} % | {:.2f} | {:+.3f} % |\n",
              gains, rate, side_name, n, humans, t.ms, t.limit,
              100.0 * (t.limit - ref.limit) / ref.limit, old.ms,
              100.0 * (old.limit - ref.limit) / ref.limit);
        }
        fmt::print("| {} | {:g} | {} | 12 (19 levels) | {} | {:.1f} | {:.2f} | reference | | |\n",
                   gains, rate, side_name, 19 * 12 * 12 * 12, ref.ms, ref.limit);
      }
    }
  }
  return 0;
}
