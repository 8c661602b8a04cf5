// Issue 18's target "NodeCore step at n = 3 <= 1 us": one cycle of an engaged n-axis master and
// slave (NodeCoreAxes::step of each: read the device, take the peer's state, the state machine,
// the n-axis law with a plane, the command, publish the state and a telemetry record), each on a
// simulated n-axis device whose physics step (SimDeviceAxes::tick, bench_device_axes) is inside
// step(). BM_NodeCoreAxesPair times both nodes' steps by the steady clock (manual time; "Time"
// is the figure, "CPU" includes the hand-over); the state hand-over and the telemetry drain
// between cycles are outside it.
#include <benchmark/benchmark.h>

#include <chrono>

#include "tests/unit/node/node_axes_test_util.hpp"

namespace {

using namespace std::chrono_literals;
using teleop::node::Command;
using teleop::node::Mode;
using teleop::node::NodeCoreAxes;
using teleop::node::PeerSample;
using teleop::transport::Role;
namespace axes_test = teleop::node::axes_test;

void BM_NodeCoreAxesPair(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  teleop::device::SimDeviceAxes master_dev(axes_test::device_config(n, true));
  teleop::device::SimDeviceAxes slave_dev(axes_test::device_config(n, false));
  for (teleop::device::SimDeviceAxes* d : {&master_dev, &slave_dev}) {
    if (!d->configure().ok() || !d->activate().ok()) {
      state.SkipWithError("device set-up failed");
      return;
    }
  }
  NodeCoreAxes master(axes_test::settings(Role::kMaster, n), master_dev);
  NodeCoreAxes slave(axes_test::settings(Role::kSlave, n), slave_dev);
  PeerSample to_master{};
  PeerSample to_slave{};
  std::chrono::nanoseconds now = 1s;
  auto hand_over = [&] {
    (void)master.state_out().read(to_slave.state);
    to_slave.arrival_ns = (now + 300us).count();
    (void)slave.state_out().read(to_master.state);
    to_master.arrival_ns = (now + 300us).count();
    while (master.telemetry_out().try_pop()) {
    }
    while (slave.telemetry_out().try_pop()) {
    }
    if (to_master.state.sequence != 0) master.peer_in().write(to_master);
    if (to_slave.state.sequence != 0) slave.peer_in().write(to_slave);
  };
  auto cycle = [&] {
    now += 1ms;
    master.step(now, now);
    slave.step(now, now);
    hand_over();
  };
  for (int i = 0; i < 3; ++i) cycle();
  for (const Command c : {Command::kArm, Command::kEngage}) {
    (void)master.post_command(c);
    (void)slave.post_command(c);
    cycle();
  }
  for (int i = 0; i < 5000 && master.mode() != Mode::kEngaged; ++i) cycle();
  if (master.mode() != Mode::kEngaged) {
    state.SkipWithError("the pair did not engage");
    return;
  }
  // Manual time around the two steps (PauseTiming costs more than a step).
  for (auto _ : state) {
    now += 1ms;
    const auto t0 = std::chrono::steady_clock::now();
    master.step(now, now);
    slave.step(now, now);
    const auto t1 = std::chrono::steady_clock::now();
    state.SetIterationTime(std::chrono::duration<double>(t1 - t0).count());
    hand_over();
  }
  if (master.mode() != Mode::kEngaged) state.SkipWithError("the pair left engaged");
  state.SetLabel("master + slave step, engaged, simulated devices");
}
BENCHMARK(BM_NodeCoreAxesPair)->Arg(1)->Arg(3)->Arg(6)->UseManualTime();

}  // namespace

BENCHMARK_MAIN();
