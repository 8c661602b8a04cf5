// The RT thread of a real node loop allocates nothing (issue 4 "Loop", docs/architecture.md §4.3):
// a master and a slave NodeApp in this process, linked over ZeroMQ on loopback, engaged with the
// human pushing into tissue; the allocator is interposed and the calls made by the master's loop
// thread are counted over 10 000 of its cycles. The sockets, protobuf and telemetry threads
// allocate freely meanwhile: they are not counted.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>

#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/device/sim_device.hpp"
#include "common/runtime/node_app.hpp"
#include "tests/integration/node_harness.hpp"
#include "tests/support/alloc_counter.hpp"

namespace teleop::runtime {
namespace {

using namespace std::chrono_literals;
using test::Ports;

std::unique_ptr<NodeApp> make_node(const config::LoadedConfig& loaded, transport::Role role,
                                   NodeAppOptions options = {}) {
  const config::NodeSetup setup = config::to_node_setup(loaded, role);
  auto device = std::make_unique<device::SimDevice>(setup.sim);
  EXPECT_TRUE(device->configure().ok());
  EXPECT_TRUE(device->activate().ok());
  return std::make_unique<NodeApp>(setup, std::move(device), std::move(options));
}

bool wait_until(const std::function<bool()>& pred, std::chrono::seconds bound = 30s) {
  const auto until = std::chrono::steady_clock::now() + bound;
  while (std::chrono::steady_clock::now() < until) {
    if (pred()) return true;
    std::this_thread::sleep_for(2ms);
  }
  return false;
}

TEST(NodeLoopRealTime, TheCounterSeesThisThreadsAllocationsOnly) {
  void* (*volatile do_malloc)(std::size_t) = &std::malloc;
  void (*volatile do_free)(void*) = &std::free;
  std::atomic<bool> go{false};
  std::thread other([&] {
    while (!go.load()) std::this_thread::yield();
    do_free(do_malloc(64));
  });
  test::start_counting(true);
  void* mine = do_malloc(64);
  do_free(mine);
  go.store(true);
  other.join();
  EXPECT_EQ(test::stop_counting(), 2);
}

TEST(NodeLoopRealTime, MasterLoopThreadMakesNoAllocationOver10000CyclesEngaged) {
  const Ports p;
  const std::string text =
      "sample_rate_hz: 1000\n"
      "master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 } " +
      test::node_section(p, true) +
      " }\n"
      "slave { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 } "
      "fixture { stiffness_N_per_m: 800 position_m: 0.004 } " +
      test::node_section(p, false) +
      " }\n"
      "gains { kpm: 600 kps: 600 kdm: 2 kds: 2 kfm: 0.5 }\n"
      "velocity_filter { cutoff_hz: 200 }\n"
      "human { fixed { mass_kg: 0.012 damping_Ns_per_m: 0.76 stiffness_N_per_m: 70 } }\n"
      "scene { duration_s: 1 human_force { sinusoid { offset_N: 1 amplitude_N: 0.5 "
      "frequency_hz: 2 } } environment { tissue { stiffness_N_per_m: 300 position_m: 0.002 } } "
      "}\n";
  const config::LoadedConfig loaded = config::load_config_text(text, "rt-test");

  // The window opens and closes on the master's loop thread, between two of its steps.
  std::atomic<long> cycles{0};
  std::atomic<bool> open_request{false};
  std::atomic<bool> open{false};
  std::atomic<long> window_cycles{0};
  std::atomic<long> calls{-1};
  NodeAppOptions options;
  options.after_step = [&] {
    cycles.fetch_add(1);
    if (open.load()) {
      if (window_cycles.fetch_add(1) + 1 == 10000) {
        calls.store(test::stop_counting());
        open.store(false);
      }
    } else if (open_request.exchange(false)) {
      test::start_counting(true);
      open.store(true);
    }
  };
  auto master = make_node(loaded, transport::Role::kMaster, options);
  auto slave = make_node(loaded, transport::Role::kSlave);
  master->start();
  slave->start();
  auto command = [&](NodeApp& n, node::Command c) {
    ASSERT_TRUE(n.core().post_command(c));
    const std::uint64_t ticket = n.core().commands_posted();
    ASSERT_TRUE(wait_until([&] { return n.core().commands_applied() >= ticket; }));
  };
  ASSERT_TRUE(wait_until([&] { return cycles.load() > 50; }));
  for (const auto c : {node::Command::kArm, node::Command::kEngage}) {
    command(*master, c);
    command(*slave, c);
  }
  ASSERT_TRUE(wait_until([&] {
    return master->core().mode() == node::Mode::kEngaged &&
           slave->core().mode() == node::Mode::kEngaged;
  }));
  open_request.store(true);
  ASSERT_TRUE(wait_until([&] { return calls.load() >= 0; }, 60s));
  const node::Mode mode = master->core().mode();
  const std::string reason = master->core().mode_reason();
  master->stop();
  slave->stop();
  EXPECT_EQ(window_cycles.load(), 10000);
  EXPECT_EQ(calls.load(), 0) << "allocator calls from the master's loop thread";
  // Still engaged: the window covered the coupled loop with the link running. A loop the host
  // did not run for longer than the peer timeout (this VM stops both cores for 30 ms and more
  // at times) rightly went safe: then the window also covered the safe path, and the run says
  // so instead of failing (no allocation was still required of it, above).
  if (mode != node::Mode::kEngaged && reason == "own loop stalled past the peer timeout") {
    GTEST_SKIP() << "inconclusive: the host stalled the loop (" << reason << ")";
  }
  EXPECT_EQ(mode, node::Mode::kEngaged) << reason;
}

}  // namespace
}  // namespace teleop::runtime
