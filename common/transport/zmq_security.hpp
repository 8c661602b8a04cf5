// CURVE keys and the link's security policy: who may talk to a node, and when plaintext is
// acceptable at all. The policy is decided here, before any socket exists, so a node that
// would send plaintext across a network refuses to start with a message naming the endpoint
// instead of silently exposing (or accepting) force commands.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "common/transport/zmq_fwd.hpp"

namespace teleop::transport {

// A CURVE key pair in Z85 text (40 characters each), the form libzmq's options and our key
// files use.
struct CurveKeyPair {
  std::string public_z85{};
  std::string secret_z85{};
};

inline constexpr std::size_t kZ85KeyChars = 40;

// A fresh key pair from libsodium's RNG; throws std::runtime_error when libzmq was built
// without CURVE (so a node cannot be configured with keys it cannot use).
[[nodiscard]] CurveKeyPair generate_curve_keypair();

// The public key belonging to `secret_z85`; throws std::invalid_argument for a malformed key.
[[nodiscard]] std::string curve_public_from_secret(std::string_view secret_z85);

// Empty when `text` is 40 valid Z85 characters that decode to a 32-byte key; otherwise
// what is wrong with it, for error messages.
[[nodiscard]] std::optional<std::string> z85_key_problem(std::string_view text);

// Key files. NAME.key holds both keys and is created with mode 0600; NAME.pub holds only the
// public key and is what gets copied to the peer. Text, so an operator can read and diff it:
//   # teleop CURVE secret key: keep private (mode 0600), give NAME.pub to the peer
//   public-key = <40 Z85 chars>
//   secret-key = <40 Z85 chars>
// Lines starting with '#' are comments ('#' is itself a Z85 character, so no trailing ones).
struct KeyFilePaths {
  std::filesystem::path secret_file{};  // NAME.key
  std::filesystem::path public_file{};  // NAME.pub
};
[[nodiscard]] KeyFilePaths key_file_paths(const std::filesystem::path& name);

// Writes both files for `name` (NAME.key, NAME.pub). Refuses (std::runtime_error naming the
// file) to replace an existing file unless `force`; neither file is touched then. Each file
// is written to a temporary and renamed, so a crash never leaves a truncated key, and the
// secret never exists with looser permissions than 0600.
KeyFilePaths write_key_files(const std::filesystem::path& name, const CurveKeyPair& keys,
                             bool force);

// Loads NAME.key. Refuses, naming the file and the problem: a missing or unreadable file, a
// file readable or writable by group or others (a leaked secret key lets anyone impersonate
// the node), a missing or malformed key, a public key that does not belong to the secret key
// (a hand-edited or mixed-up file). Throws std::runtime_error.
[[nodiscard]] CurveKeyPair load_secret_key_file(const std::filesystem::path& path);

// A peer's public key, given either as the 40-character Z85 text itself or as the path of a
// key file holding a `public-key = ` line (NAME.pub, or NAME.key). Throws std::runtime_error
// naming the text or file and the problem.
[[nodiscard]] std::string load_public_key(std::string_view text_or_file);

// True when traffic on `endpoint` cannot leave this machine: tcp:// to 127.a.b.c (dotted
// quad), localhost or [::1]; ipc://; inproc://. Anything else is treated as a network,
// including tcp://*:port and tcp://0.0.0.0:port (they bind every interface), interface
// names, source-address forms (';') and other transports: when in doubt, require keys.
[[nodiscard]] bool is_loopback_endpoint(std::string_view endpoint);

// How one socket of the link is secured.
struct LinkSecurity {
  // Allows plaintext off loopback. Keys, when given, are still used: this only lifts the
  // requirement, it never downgrades a configured CURVE link.
  bool insecure{false};
  std::optional<CurveKeyPair> own{};
  // Z85 public keys of the clients a server accepts (enforced by ZapHandler).
  std::vector<std::string> allowed_client_keys{};
  // The server's public key, for connecting sockets.
  std::optional<std::string> server_public_key{};
};

// A client's security: its key pair from `secret_key_file` and the server's public key
// (load_public_key), each only when given; plaintext when neither is.
[[nodiscard]] LinkSecurity client_security(const std::string& secret_key_file,
                                           const std::string& server_key);

// Server = the side that binds, client = the side that connects (CURVE's roles follow them).
enum class LinkRole { kServer, kClient };

enum class LinkMechanism { kPlaintext, kCurve };
[[nodiscard]] const char* to_string(LinkMechanism m);

// The mechanism `security` gives a socket on `endpoint`; throws std::invalid_argument naming
// the endpoint and what is missing when the policy forbids the setup:
//  - off loopback, CURVE is required unless `insecure`;
//  - key material that is given but incomplete for the role (a server with a key pair but no
//    allowed clients, a client with a key pair but no server key, or the reverse) is a
//    configuration mistake everywhere, loopback included, rather than a silent fallback;
//  - malformed Z85 keys.
[[nodiscard]] LinkMechanism choose_mechanism(std::string_view endpoint, LinkRole role,
                                             const LinkSecurity& security);

// Applies choose_mechanism() to `socket`, which must not be bound or connected yet. A CURVE
// server needs a ZapHandler serving `ctx` (without one, libzmq accepts every client key); its
// allowlist is registered there under a ZAP domain set on the socket. Throws
// std::invalid_argument as choose_mechanism() does, or when no ZapHandler serves `ctx`.
LinkMechanism apply_link_security(zmq::context_t& ctx, zmq::socket_t& socket,
                                  std::string_view endpoint, LinkRole role,
                                  const LinkSecurity& security);

}  // namespace teleop::transport
