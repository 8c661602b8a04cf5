#include "common/runtime/command_authority.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <zmq.hpp>

namespace teleop::runtime {

namespace {

bool contains(const std::vector<std::string>& keys, std::string_view key) {
  return std::find(keys.begin(), keys.end(), key) != keys.end();
}

std::string kind_name(v1::NodeCommand::Kind kind) {
  const std::string& n = v1::NodeCommand::Kind_Name(kind);
  return n.empty() ? fmt::format("command {}", static_cast<int>(kind)) : n;
}

}  // namespace

CommandAuthority command_authority(const config::NodeKeys& keys, bool authenticated) {
  CommandAuthority a;
  a.authenticated = authenticated;
  a.allow_unauthenticated_retune = keys.allow_unauthenticated_retune;
  a.supervisor_key = keys.supervisor_public_key;
  a.read_only_keys = keys.read_only_client_keys;
  return a;
}

Caller classify_caller(const CommandAuthority& a, std::string_view key) {
  if (!a.authenticated) return Caller::kUnauthenticated;
  if (key.empty()) return Caller::kNoIdentity;
  // Read-only first: a key listed as read-only anywhere is read-only, whatever else it is.
  if (contains(a.read_only_keys, key)) return Caller::kReadOnly;
  if (!a.supervisor_key.empty() && key == a.supervisor_key) return Caller::kSupervisor;
  return Caller::kClient;
}

const char* to_string(Caller c) {
  switch (c) {
    case Caller::kUnauthenticated:
      return "unauthenticated (plaintext)";
    case Caller::kSupervisor:
      return "supervisor";
    case Caller::kReadOnly:
      return "read-only";
    case Caller::kClient:
      return "client";
    case Caller::kNoIdentity:
      return "without identity";
  }
  return "?";
}

std::string command_refusal(const CommandAuthority& a, v1::NodeCommand::Kind kind,
                            std::string_view key) {
  // Stopping never needs authority: whoever can reach the node may stop it.
  if (kind == v1::NodeCommand::ESTOP) return {};
  const Caller caller = classify_caller(a, key);
  const std::string who = key.empty() ? std::string(to_string(caller))
                                      : fmt::format("{} key {}", to_string(caller), key);
  switch (caller) {
    case Caller::kSupervisor:
      return {};
    case Caller::kReadOnly:
      if (kind == v1::NodeCommand::STATUS) return {};
      return fmt::format(
          "{} refused: caller is the {} (security.read_only_client_public_keys): e-stop and "
          "status only",
          kind_name(kind), who);
    case Caller::kNoIdentity:
      // CURVE without a ZAP user id: nothing to decide on, so nothing but the e-stop.
      return fmt::format("{} refused: the request carries no authenticated identity",
                         kind_name(kind));
    case Caller::kClient:
      if (kind == v1::NodeCommand::RETUNE || kind == v1::NodeCommand::SHUTDOWN) {
        return fmt::format(
            "{} refused: only the supervisor's key (security.supervisor_public_key{}) may {} "
            "this node; caller is a {}",
            kind_name(kind), a.supervisor_key.empty() ? ", not set" : "",
            kind == v1::NodeCommand::RETUNE ? "retune" : "shut down", who);
      }
      return {};
    case Caller::kUnauthenticated:
      if (kind == v1::NodeCommand::RETUNE && !a.allow_unauthenticated_retune) {
        return "RETUNE refused: the command endpoint is plaintext, so the supervisor cannot be "
               "told from any other local client (give the nodes and the supervisor CURVE keys, "
               "or set security.allow_unauthenticated_retune: true)";
      }
      return {};
  }
  return "refused: unknown caller";
}

std::string caller_key(const zmq::message_t& request, bool authenticated) {
  if (!authenticated) return {};
  // zmq_msg_gets fails (EINVAL) for a property the connection does not have.
  const char* const uid = zmq_msg_gets(request.handle(), "User-Id");
  return uid == nullptr ? std::string{} : std::string(uid);
}

std::vector<std::string> admitted_client_keys(const config::NodeKeys& keys) {
  std::vector<std::string> out = keys.allowed_client_keys;
  auto add = [&out](const std::string& k) {
    if (!k.empty() && !contains(out, k)) out.push_back(k);
  };
  add(keys.supervisor_public_key);
  for (const std::string& k : keys.read_only_client_keys) add(k);
  return out;
}

std::vector<std::string> authority_warnings(const CommandAuthority& a) {
  std::vector<std::string> out;
  if (!a.authenticated) {
    out.push_back(
        a.allow_unauthenticated_retune
            ? "security.allow_unauthenticated_retune is set on a plaintext command endpoint: ANY "
              "local client may retune this node without analysis"
            : "plaintext command endpoint: every RETUNE is refused (the supervisor's guarded "
              "changes too); give the nodes and the supervisor CURVE keys, or set "
              "security.allow_unauthenticated_retune: true");
    return out;
  }
  if (a.allow_unauthenticated_retune) {
    out.push_back(
        "security.allow_unauthenticated_retune has no effect under CURVE: only the supervisor's "
        "key may retune");
  }
  if (a.supervisor_key.empty()) {
    out.push_back(
        "security.supervisor_public_key is not set: no client may retune this node (the "
        "supervisor's guarded changes are refused)");
  } else if (contains(a.read_only_keys, a.supervisor_key)) {
    out.push_back(
        "security.supervisor_public_key is also in read_only_client_public_keys: it is "
        "treated as read-only, so no client may retune this node");
  }
  return out;
}

}  // namespace teleop::runtime
