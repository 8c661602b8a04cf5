// Time of one control step (issue 4 "Benchmarks"): NodeCore::step of an engaged master and
// slave on simulated devices, against the control law's step alone and the simulated device's
// cycle alone (read, write, one period of plant and human physics: a real device does I/O
// instead), so the node's own overhead (state machine, peer hand-over, telemetry record) is the
// difference.
//
//   build/bench/bench_node_step [benchmark flags]
#include <benchmark/benchmark.h>

#include <array>
#include <chrono>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "common/device/sim_device.hpp"
#include "common/node/node_core.hpp"

namespace {

using namespace std::chrono_literals;
using namespace teleop;
using transport::Role;

// The paddles of examples/paddles.textproto at 1 kHz.
control::LawParams law() {
  control::LawParams p;
  p.period_s = 1e-3;
  p.gains = Gains{600, 600, 2, 2, 0, 0, 0};
  p.velocity_cutoff_hz = 200.0;
  p.slave_fixture.position_m = 0.02;
  p.slave_fixture.stiffness_N_per_m = 1500.0;
  return p;
}

node::NodeSettings settings(Role role) {
  node::NodeSettings s;
  s.role = role;
  s.period = 1ms;
  s.law = law();
  s.session_id = role == Role::kMaster ? 11 : 22;
  s.config_fingerprint = 0x5eed;  // the same configuration on both sides
  return s;
}

device::SimDeviceConfig master_device() {
  sim::HumanParams h;
  h.impedance = HumanImpedance{0.012, 0.76, 70.0};
  h.profile = sim::ForceProfile::constant(0.5);
  device::SimDeviceConfig c = device::SimDeviceConfig::paddle_master(h);
  c.hold_scene_until_engaged = true;
  return c;
}

device::SimDevice& started(device::SimDevice& d) {
  if (!d.configure().ok() || !d.activate().ok()) throw std::runtime_error("device did not start");
  return d;
}

// A master and a slave node engaged by exchanging states by hand (as the link threads would,
// 0.3 ms after sending), as in tests/unit/node/test_node_core.cpp.
struct EngagedPair {
  EngagedPair()
      : master_dev(master_device()),
        slave_dev(device::SimDeviceConfig::paddle_slave(sim::Environment::free_space())),
        master(settings(Role::kMaster), started(master_dev)),
        slave(settings(Role::kSlave), started(slave_dev)) {
    for (int i = 0; i < 3; ++i) cycle();
    (void)master.post_command(node::Command::kArm);
    (void)slave.post_command(node::Command::kArm);
    cycle();
    (void)master.post_command(node::Command::kEngage);
    (void)slave.post_command(node::Command::kEngage);
    for (int i = 0; i < 3000; ++i) {
      cycle();
      if (master.mode() == node::Mode::kEngaged && slave.mode() == node::Mode::kEngaged) break;
    }
    if (master.mode() != node::Mode::kEngaged || slave.mode() != node::Mode::kEngaged) {
      throw std::runtime_error("the pair did not engage");
    }
    for (int i = 0; i < 100; ++i) cycle();  // past the engage ramp
  }
  void cycle() {
    now += 1ms;
    if (to_master.state.sequence != 0) master.peer_in().write(to_master);
    if (to_slave.state.sequence != 0) slave.peer_in().write(to_slave);
    master.step(now);
    slave.step(now);
    (void)master.state_out().read(to_slave.state);
    to_slave.arrival_ns = (now + 300us).count();
    (void)slave.state_out().read(to_master.state);
    to_master.arrival_ns = (now + 300us).count();
    drain();
  }
  void drain() {
    while (master.telemetry_out().try_pop()) {
    }
    while (slave.telemetry_out().try_pop()) {
    }
  }

  device::SimDevice master_dev;
  device::SimDevice slave_dev;
  node::NodeCore master;
  node::NodeCore slave;
  std::chrono::nanoseconds now{1s};
  node::PeerSample to_master{};
  node::PeerSample to_slave{};
};

// One side steps; the other side's newest state is handed over every cycle with a fresh
// sequence echoing ours, as from a peer that keeps up.
void step_one_side(benchmark::State& state, bool master_side) {
  EngagedPair p;
  node::NodeCore& core = master_side ? p.master : p.slave;
  node::NodeCore& other = master_side ? p.slave : p.master;
  node::PeerSample& incoming = master_side ? p.to_master : p.to_slave;
  transport::NodeStateRecord own;
  std::uint64_t i = 0;
  for (auto _ : state) {
    p.now += 1ms;
    ++incoming.state.sequence;
    incoming.state.last_peer_sequence = own.sequence;
    incoming.arrival_ns = (p.now - 700us).count();
    core.peer_in().write(incoming);
    core.step(p.now);
    (void)core.state_out().read(own);
    if ((++i & 1023U) == 0) {
      state.PauseTiming();
      p.drain();
      state.ResumeTiming();
    }
  }
  if (core.mode() != node::Mode::kEngaged || other.mode() != node::Mode::kEngaged) {
    state.SkipWithError("left the engaged mode");
  }
}

void BM_NodeStep_MasterEngaged(benchmark::State& state) { step_one_side(state, true); }
BENCHMARK(BM_NodeStep_MasterEngaged);

void BM_NodeStep_SlaveEngaged(benchmark::State& state) { step_one_side(state, false); }
BENCHMARK(BM_NodeStep_SlaveEngaged);

// Positions along a 1 Hz, 1 cm sine, so the law's filters see motion.
std::array<double, 1000> trajectory() {
  std::array<double, 1000> x{};
  for (std::size_t i = 0; i < x.size(); ++i) {
    x[i] = 0.01 * std::sin(2.0 * std::numbers::pi * static_cast<double>(i) * 1e-3);
  }
  return x;
}

void BM_MasterLaw_Step(benchmark::State& state) {
  control::MasterLaw m(law());
  const std::array<double, 1000> x = trajectory();
  control::PeerState slave{0.0, 0.0, 0.0, false, true};
  std::size_t i = 0;
  for (auto _ : state) {
    slave.position_m = x[(i + 3) % x.size()];
    benchmark::DoNotOptimize(m.step(x[i], slave));
    i = (i + 1) % x.size();
  }
}
BENCHMARK(BM_MasterLaw_Step);

void BM_SlaveLaw_Step(benchmark::State& state) {
  control::SlaveLaw s(law());
  const std::array<double, 1000> x = trajectory();
  control::PeerState master{0.0, 0.0, 0.0, false, true};
  std::size_t i = 0;
  for (auto _ : state) {
    master.position_m = x[(i + 3) % x.size()];
    benchmark::DoNotOptimize(s.step(x[i], 0.0, master));
    i = (i + 1) % x.size();
  }
}
BENCHMARK(BM_SlaveLaw_Step);

// What the master's step spends in the simulated device: read, write, one period of physics.
void BM_SimDevice_MasterCycle(benchmark::State& state) {
  device::SimDevice d(master_device());
  started(d);
  d.on_engaged();
  device::Sample sample{};
  for (auto _ : state) {
    (void)d.read(sample);
    (void)d.write(device::Command{-100.0 * sample.position_m});
    benchmark::DoNotOptimize(d.tick(1ms));
  }
}
BENCHMARK(BM_SimDevice_MasterCycle);

}  // namespace

BENCHMARK_MAIN();
