// The link thread's cost of NodeState with n task-space axes (issue 18; common/transport/
// node_state_codec.hpp): encode() on the sender thread and PeerStateFilter::accept() on the
// receiver thread at n = 1, 3 and 6. Neither runs on the RT thread. The wire size is reported as
// the counter `bytes`.
//
//   build/bench/bench_node_state_axes [benchmark flags]
#include <benchmark/benchmark.h>

#include <cstdint>
#include <string>

#include "common/transport/node_state_codec.hpp"

namespace {

using teleop::transport::NodeStateRecord;
using teleop::transport::PeerStateFilter;
using teleop::transport::Role;

NodeStateRecord record(int n, std::uint64_t seq) {
  NodeStateRecord r;
  r.session_id = 0x5EC0'0003'0A0E'5EEDULL;
  r.sequence = seq;
  r.sample_time_ns = static_cast<std::int64_t>(seq) * 1'000'000;
  r.last_peer_sequence = seq;
  r.peer_age_ns = 300'000;
  r.role = Role::kMaster;
  r.mode = 4;
  r.fixture_in_contact = true;
  r.fixture_penetration_m = 4e-4;
  r.fixture_force_N = 1.2;
  r.config_fingerprint = 0x1122'3344'5566'7788ULL;
  r.axes = n;
  for (int j = 0; j < n; ++j) {
    r.set_axis(static_cast<std::size_t>(j), 0.01 + 1e-3 * j, -0.02 * j, 0.5 + j);
  }
  return r;
}

void BM_Encode(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  NodeStateRecord r = record(n, 1);
  std::size_t bytes = 0;
  for (auto _ : state) {
    ++r.sequence;
    const std::string wire = teleop::transport::encode(r);
    bytes = wire.size();
    benchmark::DoNotOptimize(wire.data());
  }
  state.counters["bytes"] = static_cast<double>(bytes);
}
BENCHMARK(BM_Encode)->Arg(1)->Arg(3)->Arg(6);

void BM_Accept(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  // Distinct sequences, so every state is accepted (none stale).
  constexpr std::uint64_t kStates = 4096;
  std::string wire[kStates];
  for (std::uint64_t i = 0; i < kStates; ++i) wire[i] = teleop::transport::encode(record(n, i + 1));
  PeerStateFilter filter(Role::kMaster, n);
  std::uint64_t i = 0;
  for (auto _ : state) {
    if (i == kStates) {
      state.PauseTiming();
      filter = PeerStateFilter(Role::kMaster, n);
      i = 0;
      state.ResumeTiming();
    }
    auto got = filter.accept(wire[i++]);
    benchmark::DoNotOptimize(got);
  }
  if (filter.accepted() == 0) state.SkipWithError("nothing accepted");
}
BENCHMARK(BM_Accept)->Arg(1)->Arg(3)->Arg(6);

}  // namespace

BENCHMARK_MAIN();
