// Who may command a node (issue 14 "Authority"): the decision table of command_refusal(), the
// node's allowlist, and the caller's key as the ZAP handler hands it over on real CURVE
// sockets — and not taken from a plaintext peer that claims one in its own ZMTP metadata.
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <chrono>
#include <zmq.hpp>

#include "common/runtime/command_authority.hpp"
#include "common/transport/zap_handler.hpp"
#include "common/transport/zmq_security.hpp"

namespace teleop::runtime {
namespace {

using K = v1::NodeCommand;

const transport::CurveKeyPair& supervisor_keys() {
  static const transport::CurveKeyPair k = transport::generate_curve_keypair();
  return k;
}
const transport::CurveKeyPair& console_keys() {
  static const transport::CurveKeyPair k = transport::generate_curve_keypair();
  return k;
}
const transport::CurveKeyPair& viewer_keys() {
  static const transport::CurveKeyPair k = transport::generate_curve_keypair();
  return k;
}

CommandAuthority curve_authority() {
  CommandAuthority a;
  a.authenticated = true;
  a.supervisor_key = supervisor_keys().public_z85;
  a.read_only_keys = {viewer_keys().public_z85};
  return a;
}

const std::vector<K::Kind> kEveryKind = {K::ARM,      K::ENGAGE, K::DISENGAGE,    K::CLUTCH,
                                         K::UNCLUTCH, K::CLEAR,  K::ESTOP,        K::STATUS,
                                         K::SHUTDOWN, K::RETUNE, K::FLIGHT_RECORD};

TEST(CommandAuthority, TheSupervisorsKeyMayDoEverything) {
  const CommandAuthority a = curve_authority();
  for (const K::Kind k : kEveryKind) {
    EXPECT_TRUE(command_allowed(a, k, supervisor_keys().public_z85)) << K::Kind_Name(k);
  }
  EXPECT_EQ(classify_caller(a, supervisor_keys().public_z85), Caller::kSupervisor);
}

TEST(CommandAuthority, AClientKeyMayNeitherRetuneNorShutDown) {
  const CommandAuthority a = curve_authority();
  const std::string& key = console_keys().public_z85;
  for (const K::Kind k : kEveryKind) {
    const bool want = k != K::RETUNE && k != K::SHUTDOWN;
    EXPECT_EQ(command_allowed(a, k, key), want) << K::Kind_Name(k);
  }
  const std::string why = command_refusal(a, K::RETUNE, key);
  EXPECT_NE(why.find("RETUNE refused"), std::string::npos) << why;
  EXPECT_NE(why.find("security.supervisor_public_key"), std::string::npos) << why;
  EXPECT_NE(why.find(key), std::string::npos) << why;
}

TEST(CommandAuthority, AReadOnlyKeyMayOnlyEstopAndAskForStatus) {
  const CommandAuthority a = curve_authority();
  const std::string& key = viewer_keys().public_z85;
  for (const K::Kind k : kEveryKind) {
    EXPECT_EQ(command_allowed(a, k, key), k == K::ESTOP || k == K::STATUS) << K::Kind_Name(k);
  }
  EXPECT_NE(command_refusal(a, K::ARM, key).find("read-only"), std::string::npos);
}

TEST(CommandAuthority, ReadOnlyWinsOverTheSupervisorsKeyListedAsReadOnly) {
  CommandAuthority a = curve_authority();
  a.read_only_keys.push_back(a.supervisor_key);
  EXPECT_FALSE(command_allowed(a, K::RETUNE, a.supervisor_key));
  EXPECT_TRUE(command_allowed(a, K::ESTOP, a.supervisor_key));
  const auto w = authority_warnings(a);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_NE(w[0].find("read_only_client_public_keys"), std::string::npos) << w[0];
}

TEST(CommandAuthority, WithoutASupervisorKeyNobodyRetunesUnderCurve) {
  CommandAuthority a = curve_authority();
  a.supervisor_key.clear();
  a.allow_unauthenticated_retune = true;  // no effect under CURVE
  EXPECT_FALSE(command_allowed(a, K::RETUNE, console_keys().public_z85));
  EXPECT_FALSE(command_allowed(a, K::RETUNE, supervisor_keys().public_z85));
  EXPECT_EQ(authority_warnings(a).size(), 2u);
}

TEST(CommandAuthority, UnderCurveARequestWithoutIdentityMayOnlyEstop) {
  const CommandAuthority a = curve_authority();
  for (const K::Kind k : kEveryKind) {
    EXPECT_EQ(command_allowed(a, k, ""), k == K::ESTOP) << K::Kind_Name(k);
  }
}

TEST(CommandAuthority, PlaintextRefusesRetuneUnlessOptedInByName) {
  CommandAuthority a;
  a.authenticated = false;
  a.supervisor_key = supervisor_keys().public_z85;
  for (const K::Kind k : kEveryKind) {
    EXPECT_EQ(command_allowed(a, k, ""), k != K::RETUNE) << K::Kind_Name(k);
  }
  // A key claimed without authentication is nobody's.
  EXPECT_FALSE(command_allowed(a, K::RETUNE, supervisor_keys().public_z85));
  EXPECT_NE(command_refusal(a, K::RETUNE, "").find("allow_unauthenticated_retune"),
            std::string::npos);
  auto w = authority_warnings(a);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_NE(w[0].find("every RETUNE is refused"), std::string::npos) << w[0];

  a.allow_unauthenticated_retune = true;
  EXPECT_TRUE(command_allowed(a, K::RETUNE, ""));
  w = authority_warnings(a);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_NE(w[0].find("ANY local client may retune"), std::string::npos) << w[0];
}

TEST(CommandAuthority, NodesAdmitTheSupervisorAndReadOnlyKeysOnce) {
  config::NodeKeys keys;
  keys.allowed_client_keys = {console_keys().public_z85, supervisor_keys().public_z85};
  keys.supervisor_public_key = supervisor_keys().public_z85;
  keys.read_only_client_keys = {viewer_keys().public_z85};
  const std::vector<std::string> admitted = admitted_client_keys(keys);
  EXPECT_EQ(admitted,
            (std::vector<std::string>{console_keys().public_z85, supervisor_keys().public_z85,
                                      viewer_keys().public_z85}));
}

// --- the caller's key on real sockets ----------------------------------------------------

std::string bound(zmq::socket_t& s) { return s.get(zmq::sockopt::last_endpoint); }

zmq::message_t receive(zmq::socket_t& s) {
  zmq::pollitem_t item{s.handle(), 0, ZMQ_POLLIN, 0};
  EXPECT_GT(zmq::poll(&item, 1, std::chrono::milliseconds{5000}), 0);
  zmq::message_t m;
  EXPECT_TRUE(s.recv(m, zmq::recv_flags::dontwait));
  return m;
}

TEST(CommandAuthorityZap, EachCurveConnectionCarriesItsClientsKeyAsUserId) {
  zmq::context_t ctx;
  transport::ZapHandler zap(ctx);
  const transport::CurveKeyPair server = transport::generate_curve_keypair();
  transport::LinkSecurity sec;
  sec.own = server;
  sec.allowed_client_keys = {console_keys().public_z85, supervisor_keys().public_z85};
  zmq::socket_t rep(ctx, zmq::socket_type::rep);
  rep.set(zmq::sockopt::linger, 0);
  ASSERT_EQ(transport::apply_link_security(ctx, rep, "tcp://127.0.0.1:*",
                                           transport::LinkRole::kServer, sec),
            transport::LinkMechanism::kCurve);
  rep.bind("tcp://127.0.0.1:*");
  for (const transport::CurveKeyPair* client : {&console_keys(), &supervisor_keys()}) {
    zmq::socket_t req(ctx, zmq::socket_type::req);
    req.set(zmq::sockopt::linger, 0);
    req.set(zmq::sockopt::curve_serverkey, server.public_z85);
    req.set(zmq::sockopt::curve_publickey, client->public_z85);
    req.set(zmq::sockopt::curve_secretkey, client->secret_z85);
    req.connect(bound(rep));
    req.send(zmq::str_buffer("hello"), zmq::send_flags::none);
    const zmq::message_t m = receive(rep);
    EXPECT_EQ(caller_key(m, true), client->public_z85);
    // Not read at all when the endpoint is not authenticated.
    EXPECT_EQ(caller_key(m, false), "");
    rep.send(zmq::str_buffer("ok"), zmq::send_flags::none);
    zmq::message_t reply;
    ASSERT_TRUE(req.recv(reply));
  }
}

// A raw ZMTP 3.0 NULL peer's greeting and READY, claiming `user_id`.
std::string zmtp_null_handshake(const std::string& user_id) {
  std::string w(64, '\0');
  w[0] = static_cast<char>(0xFF);
  w[9] = 0x7F;
  w[10] = 3;
  w.replace(12, 4, "NULL");
  auto property = [](const std::string& name, const std::string& value) {
    std::string s(1, static_cast<char>(name.size()));
    s += name;
    const auto n = static_cast<std::uint32_t>(value.size());
    for (int shift = 24; shift >= 0; shift -= 8) s += static_cast<char>((n >> shift) & 0xFF);
    return s + value;
  };
  const std::string ready =
      std::string("\x05READY", 6) + property("Socket-Type", "REQ") + property("User-Id", user_id);
  w += static_cast<char>(0x04);
  w += static_cast<char>(ready.size());
  return w + ready;
}

// One short REQ message: the empty delimiter, then `body`.
std::string zmtp_req_message(const std::string& body) {
  std::string w("\x01\x00", 2);
  w += static_cast<char>(0x00);
  w += static_cast<char>(body.size());
  return w + body;
}

// Reads until the server's READY arrived (a message sent before that would land in the
// server's handshake and be refused as an unexpected command).
void await_ready(int fd) {
  std::string in;
  timeval tv{5, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  char buf[512];
  while (in.find("READY") == std::string::npos) {
    const ssize_t n = ::recv(fd, buf, sizeof(buf), 0);
    if (n <= 0) break;
    in.append(buf, static_cast<std::size_t>(n));
  }
}

TEST(CommandAuthorityZap, APlaintextPeersClaimedUserIdIsIgnored) {
  zmq::context_t ctx;
  zmq::socket_t rep(ctx, zmq::socket_type::rep);
  rep.set(zmq::sockopt::linger, 0);
  rep.bind("tcp://127.0.0.1:*");
  const std::string endpoint = bound(rep);
  const int port = std::stoi(endpoint.substr(endpoint.rfind(':') + 1));
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)), 0);
  const std::string hello = zmtp_null_handshake(supervisor_keys().public_z85);
  ASSERT_EQ(::send(fd, hello.data(), hello.size(), 0), static_cast<ssize_t>(hello.size()));
  await_ready(fd);
  const std::string wire = zmtp_req_message("retune");
  ASSERT_EQ(::send(fd, wire.data(), wire.size(), 0), static_cast<ssize_t>(wire.size()));
  const zmq::message_t m = receive(rep);
  EXPECT_EQ(m.to_string(), "retune");
  // libzmq hands the peer's own metadata over under that name: the claim is real...
  const char* claimed = zmq_msg_gets(m.handle(), "User-Id");
  ASSERT_NE(claimed, nullptr) << "libzmq no longer passes peer metadata named User-Id";
  EXPECT_EQ(std::string(claimed), supervisor_keys().public_z85);
  // ...and the node never reads it on a plaintext endpoint.
  EXPECT_EQ(caller_key(m, false), "");
  CommandAuthority plain;
  plain.supervisor_key = supervisor_keys().public_z85;
  EXPECT_FALSE(command_allowed(plain, K::RETUNE, caller_key(m, plain.authenticated)));
  ::close(fd);
}

}  // namespace
}  // namespace teleop::runtime
