// Writes a session as teleop-supervisor records one (issue 17), for the official reader check
// (ctest -R supervisor.session_mcap_js, tests/mcap_js/verify.mjs --session): SupervisorCore
// with the real session recorder, its log times on the wall clock (the daemon's offset: core
// clock = CLOCK_MONOTONIC), fed 2 s of 1 kHz telemetry from both nodes in 20-cycle batches and
// a slave restart, which raises a WARNING alarm (and so a foxglove.Log).
//   usage: supervised_session_sample CONFIG OUTPUT.mcap
#include <time.h>

#include <cstdio>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>

#include "common/config/config_loader.hpp"
#include "common/record/session_recorder.hpp"
#include "supervisor/core/session_output.hpp"
#include "supervisor/core/supervisor_core.hpp"

namespace {

using teleop::supervisor::Side;
constexpr std::int64_t kMs = 1'000'000;

std::int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

class NoNodes final : public teleop::supervisor::SupervisorPorts {
 public:
  std::optional<teleop::v1::NodeCommandReply> command(Side,
                                                      const teleop::v1::NodeCommand&) override {
    return std::nullopt;
  }
  void report(const teleop::v1::StabilityReport&) override {}
  void alarm(const teleop::v1::Alarm&) override {}
  void status(const teleop::v1::SupervisorStatus&) override {}
};

// 20 cycles ending at cycle `last` (sample time = cycle x 1 ms on the node's clock).
teleop::v1::Telemetry batch(bool master, std::uint64_t session, std::uint64_t last) {
  teleop::v1::Telemetry t;
  t.set_session_id(session);
  t.set_role(master ? teleop::v1::MASTER : teleop::v1::SLAVE);
  t.set_mode(teleop::v1::ARMED);
  t.mutable_rt()->set_fifo_priority(80);
  t.mutable_rt()->set_memory_locked(true);
  for (std::uint64_t c = last - 19; c <= last; ++c) {
    teleop::v1::CycleRecord* r = t.add_cycles();
    r->set_sequence(c);
    r->set_sample_time_ns(static_cast<std::int64_t>(c) * kMs);
    r->set_mode(teleop::v1::ARMED);
    r->set_position_m(1e-3 * static_cast<double>(c % 17));
  }
  return t;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: %s CONFIG OUTPUT.mcap\n", argv[0]);
    return 2;
  }
  try {
    const teleop::config::LoadedConfig loaded = teleop::config::load_config_file(argv[1]);
    std::ifstream in(argv[1], std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    NoNodes ports;
    teleop::supervisor::SupervisorOptions o;
    o.sink = teleop::record::make_session_recorder_at(argv[2]);
    o.config_text = text.str();
    const std::int64_t t0 = monotonic_ns();
    o.log_time_offset_ns = teleop::supervisor::wall_clock_ns() - t0;
    {
      teleop::supervisor::SupervisorCore core(loaded, std::move(o), ports);
      core.start(t0);
      // 2 s: 100 batches per node, the slave restarting (a new session) after 1 s.
      for (std::uint64_t b = 1; b <= 100; ++b) {
        const std::int64_t now = t0 + static_cast<std::int64_t>(b) * 20 * kMs;
        core.on_telemetry(Side::kMaster, batch(true, 11, 20 * b), now);
        core.on_telemetry(Side::kSlave, batch(false, b <= 50 ? 22 : 23, 20 * b), now);
      }
    }  // the recorder closes with the core's sink
    std::printf("supervised_session_sample: wrote %s\n", argv[2]);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "supervised_session_sample: %s\n", e.what());
    return 1;
  }
  return 0;
}
