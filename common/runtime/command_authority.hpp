// Who may command a node (issue 14 "Authority"). The command endpoint's ZAP handler admits a
// CURVE client only with an allowlisted key and hands the connection that key as its ZeroMQ
// "User-Id"; the command thread asks command_allowed() for each request with it:
//  - the supervisor's key (security.supervisor_public_key): everything, and it alone RETUNE;
//  - a read-only key (security.read_only_client_public_keys): ESTOP and STATUS only, so a
//    read-only console can always stop the robot, even with the supervisor down;
//  - any other admitted key (security.client_public_keys, the peer): the state commands, the
//    flight recorder and status, never RETUNE or SHUTDOWN;
//  - a plaintext endpoint (loopback, no keys) cannot tell callers apart: every caller may send
//    the state commands, but RETUNE only with security.allow_unauthenticated_retune.
// ESTOP is allowed to every caller that reaches the endpoint: stopping never needs authority.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "common/config/node_loader.hpp"
#include "teleop/v1/telemetry.pb.h"

namespace zmq {
class message_t;
}  // namespace zmq

namespace teleop::runtime {

struct CommandAuthority {
  // The command endpoint runs CURVE: every request carries its client's key from ZAP.
  bool authenticated{false};
  bool allow_unauthenticated_retune{false};
  std::string supervisor_key{};  // Z85; empty: no supervisor identity, so no RETUNE under CURVE
  std::vector<std::string> read_only_keys{};
};

// The node's authority from its keys; `authenticated` when its server sockets run CURVE.
[[nodiscard]] CommandAuthority command_authority(const config::NodeKeys& keys, bool authenticated);

// What a caller is, from its key (Z85; empty: no ZAP User-Id).
enum class Caller { kUnauthenticated, kSupervisor, kReadOnly, kClient, kNoIdentity };
[[nodiscard]] Caller classify_caller(const CommandAuthority& a, std::string_view key);
[[nodiscard]] const char* to_string(Caller c);

// Empty when `kind` from the caller with `key` may be applied; otherwise the refusal, naming
// the command, the caller and what it may do (sent back in NodeCommandReply.message).
[[nodiscard]] std::string command_refusal(const CommandAuthority& a, v1::NodeCommand::Kind kind,
                                          std::string_view key);
[[nodiscard]] inline bool command_allowed(const CommandAuthority& a, v1::NodeCommand::Kind kind,
                                          std::string_view key) {
  return command_refusal(a, kind, key).empty();
}

// The caller's key of a request received on a server socket: the ZAP User-Id when the
// endpoint is authenticated, otherwise empty. Under plaintext the property is not read at all:
// a NULL-mechanism peer can put any "User-Id" into its own ZMTP metadata.
[[nodiscard]] std::string caller_key(const zmq::message_t& request, bool authenticated);

// The client keys a CURVE node admits on its server sockets: the loader's (peer, client
// keys), the supervisor's and the read-only consoles' (what each may do is decided per request).
[[nodiscard]] std::vector<std::string> admitted_client_keys(const config::NodeKeys& keys);

// What the node says at start about its authority (warnings, one line each).
[[nodiscard]] std::vector<std::string> authority_warnings(const CommandAuthority& a);

}  // namespace teleop::runtime
