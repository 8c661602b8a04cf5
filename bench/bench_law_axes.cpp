// Time of one master + one slave step of the n-axis law (issue 18 "Law"; common/control/
// law_axes.hpp) at n = 1, 3 and 6, with coupled gain matrices, two planes per side, the
// velocity filter and limits on every axis, against the one-axis MasterLaw + SlaveLaw on the
// same numbers. The two sides exchange their peer states every step, as the nodes do.
//
//   build/bench/bench_law_axes [benchmark flags]
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "common/control/law_axes.hpp"
#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "tests/unit/control/law_axes_test_util.hpp"

namespace {

using namespace teleop::control;

constexpr double kT = 1e-3;
constexpr int kTrajectory = 4096;

LawAxesParams params(int n) {
  using test::coupled_gain;
  LawAxesParams p;
  p.axes = n;
  p.period_s = kT;
  p.gains = {coupled_gain(n, 600.0, 30.0), coupled_gain(n, 600.0, 30.0), coupled_gain(n, 2.0, 0.1),
             coupled_gain(n, 2.0, 0.1),    coupled_gain(n, 0.5, 0.0),    coupled_gain(n, 0.5, 0.0),
             coupled_gain(n, 0.2, 0.0)};
  p.master_planes.add({test::tilted_normal(n), 0.015, 1000.0});
  p.master_planes.add({test::first_axis(n), 0.01, 800.0});
  p.slave_planes.add({test::tilted_normal(n), 0.02, 1500.0});
  p.slave_planes.add({-test::first_axis(n), 0.01, 800.0});
  p.velocity_cutoff_hz = 200.0;
  p.master_actuator = test::actuator_limits(n, 5.0, 5000.0);
  p.slave_actuator = test::actuator_limits(n, 8.0, 8000.0);
  p.slave_limits = test::slave_box(n, -0.05, 0.05, 2.0, 10.0);
  return p;
}

std::vector<AxisVector> trajectory(int n, double amplitude_m, double phase) {
  std::vector<AxisVector> x(kTrajectory);
  for (std::size_t k = 0; k < x.size(); ++k) {
    x[k] = AxisVector::Zero(n);
    for (int i = 0; i < n; ++i) {
      x[k](i) = amplitude_m * std::sin(0.01 * static_cast<double>(k) + phase + 0.7 * i);
    }
  }
  return x;
}

void BM_LawAxesStep(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const LawAxesParams p = params(n);
  MasterLawAxes master(p);
  SlaveLawAxes slave(p);
  const std::vector<AxisVector> xm = trajectory(n, 0.02, 0.0);
  const std::vector<AxisVector> xs = trajectory(n, 0.021, 0.05);
  const AxisVector fe = AxisVector::Constant(n, 0.3);
  PeerStateAxes to_slave;
  PeerStateAxes to_master;
  std::size_t k = 0;
  for (auto _ : state) {
    const CommandAxes cm = master.step(xm[k], to_master);
    const CommandAxes cs = slave.step(xs[k], fe, to_slave);
    to_slave = master.peer_state();
    to_master = slave.peer_state();
    benchmark::DoNotOptimize(cm);
    benchmark::DoNotOptimize(cs);
    k = (k + 1) % xm.size();
  }
}
BENCHMARK(BM_LawAxesStep)->Arg(1)->Arg(3)->Arg(6);

// The one-axis laws on axis 0's numbers (one plane per side: the tilted one is the axis).
void BM_OneAxisLawStep(benchmark::State& state) {
  LawParams p;
  p.period_s = kT;
  p.gains = {600.0, 600.0, 2.0, 2.0, 0.5, 0.5, 0.2};
  p.master_fixture = {1000.0, 0.015};
  p.slave_fixture = {1500.0, 0.02};
  p.velocity_cutoff_hz = 200.0;
  p.master_actuator = {5.0, 5000.0};
  p.slave_actuator = {8.0, 8000.0};
  p.slave_limits = {-0.05, 0.05, 2.0, 10.0};
  MasterLaw master(p);
  SlaveLaw slave(p);
  const std::vector<AxisVector> xm = trajectory(1, 0.02, 0.0);
  const std::vector<AxisVector> xs = trajectory(1, 0.021, 0.05);
  PeerState to_slave;
  PeerState to_master;
  std::size_t k = 0;
  for (auto _ : state) {
    const Command cm = master.step(xm[k](0), to_master);
    const Command cs = slave.step(xs[k](0), 0.3, to_slave);
    to_slave = master.peer_state();
    to_master = slave.peer_state();
    benchmark::DoNotOptimize(cm);
    benchmark::DoNotOptimize(cs);
    k = (k + 1) % xm.size();
  }
}
BENCHMARK(BM_OneAxisLawStep);

}  // namespace

BENCHMARK_MAIN();
