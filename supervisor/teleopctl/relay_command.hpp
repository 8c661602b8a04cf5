// `teleopctl relay`: the project's fault-injecting relay for one direction of a node link
// (issues 7 and 8; the kernel's netem is not available on every machine). It subscribes to a
// node's NodeState publisher and re-publishes every message on an endpoint of its own, after a
// delay and with seeded random drops, duplicates, reorders and blackouts; the peer connects
// to the relay (its node.peer_state_endpoint) instead of the node. Messages are forwarded
// as opaque frames: it works on plaintext links (loopback, test networks).
#pragma once

#include <cstdint>
#include <ostream>
#include <random>
#include <string>
#include <vector>

namespace teleop::ctl {

struct RelayFaults {
  double delay_ms{0.0};
  double jitter_ms{0.0};  // uniform in [-jitter, +jitter] on top of the delay (never negative)
  double drop{0.0};       // probabilities in [0, 1]
  double duplicate{0.0};
  double reorder{0.0};         // held back until after the next message
  double blackout_at_s{-1.0};  // from the first message; < 0: none
  double blackout_ms{0.0};     // every message in the blackout is dropped
  // Jitter as on one TCP connection: a message never overtakes the one before it (its send
  // time is at least the previous one's).
  bool in_order{false};
  std::uint64_t seed{1};
};

// What the relay decided for one received message: the delays (ms after receipt) of the copies
// it will send (none: dropped), and whether it is held back to go out after the next message.
struct RelayPlan {
  std::vector<double> delays_ms{};
  bool hold{false};
};

// The decisions, deterministic for a seed; exposed for tests.
class RelayPlanner {
 public:
  explicit RelayPlanner(const RelayFaults& faults);
  // `since_first_s`: time of this message since the first one.
  [[nodiscard]] RelayPlan plan(double since_first_s);
  std::uint64_t received{0}, dropped{0}, duplicated{0}, reordered{0}, blacked_out{0};

 private:
  RelayFaults f_;
  std::mt19937_64 rng_;
  double last_send_ms_{-1e300};  // since the first message (in_order)
};

[[nodiscard]] std::string relay_usage();
int run_relay(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

}  // namespace teleop::ctl
