// The node link's ZeroMQ layer on real sockets over tcp://127.0.0.1 with kernel-chosen ports
// (so parallel tests never collide): who gets in (the CURVE allowlist), when plaintext is
// refused, that the state stream delivers the newest message rather than a backlog, and the
// key files an operator creates with `teleopctl keygen`. Nothing waits for time to pass:
// each wait polls for a condition under a generous deadline, and "receives nothing" is judged
// against a good client in the same test that did receive.
#include <gtest/gtest.h>
#include <stdlib.h>
#include <sys/stat.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <future>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>
#include <zmq.hpp>

#include "common/transport/zap_handler.hpp"
#include "common/transport/zmq_security.hpp"
#include "common/transport/zmq_sockets.hpp"
#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/keygen_command.hpp"

namespace teleop::transport {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;
using Clock = std::chrono::steady_clock;

// Generous: only a broken link takes this long; a working one answers in milliseconds.
constexpr std::chrono::seconds kDeadline{5};
constexpr milliseconds kPollStep{5};
constexpr const char* kAnyLoopbackPort = "tcp://127.0.0.1:*";

void send_text(zmq::socket_t& socket, const std::string& text) {
  ASSERT_TRUE(socket.send(zmq::buffer(text), zmq::send_flags::dontwait).has_value());
}

// Matches a message containing every fragment, for error-message checks.
template <typename Exception, typename F>
std::string message_of(F&& f) {
  try {
    f();
  } catch (const Exception& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected an exception";
  return {};
}

struct Peers {
  CurveKeyPair server{generate_curve_keypair()};
  CurveKeyPair good{generate_curve_keypair()};
  CurveKeyPair stranger{generate_curve_keypair()};

  [[nodiscard]] LinkSecurity server_security() const {
    return LinkSecurity{false, server, {good.public_z85}, std::nullopt};
  }
  [[nodiscard]] LinkSecurity client_security(const CurveKeyPair& own,
                                             const std::string& server_key) const {
    return LinkSecurity{false, own, {}, server_key};
  }
};

// Publishes numbered messages until `subscriber` has received one numbered at least
// `from`; returns the number received (empty if the deadline passed). The subscriber's own
// receive timeout paces the loop.
std::optional<int> pump_until_received(zmq::socket_t& publisher, zmq::socket_t& subscriber,
                                       int& next, int from) {
  const auto deadline = Clock::now() + kDeadline;
  while (Clock::now() < deadline) {
    send_text(publisher, std::to_string(next++));
    if (const auto got = recv_latest(subscriber, kPollStep)) {
      const int n = std::stoi(*got);
      if (n >= from) return n;
    }
  }
  return std::nullopt;
}

// Reports the server side's rejected handshakes (bad box, wrong key), which happen before
// ZAP is asked and so are not counted by the ZapHandler.
class HandshakeFailures {
 public:
  HandshakeFailures(zmq::context_t& ctx, zmq::socket_t& monitored)
      : pair_(ctx, zmq::socket_type::pair) {
    const std::string address =
        "inproc://test.monitor." + std::to_string(reinterpret_cast<std::uintptr_t>(this));
    const int rc = zmq_socket_monitor(monitored.handle(), address.c_str(),
                                      ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL |
                                          ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL |
                                          ZMQ_EVENT_HANDSHAKE_FAILED_AUTH);
    EXPECT_EQ(rc, 0) << zmq_strerror(zmq_errno());
    pair_.set(zmq::sockopt::linger, 0);
    pair_.connect(address);
  }
  // Counts failures reported so far; waits up to `timeout` for the first.
  int poll(milliseconds timeout) {
    zmq::pollitem_t item{pair_.handle(), 0, ZMQ_POLLIN, 0};
    if (zmq::poll(&item, 1, timeout) == 0) return count_;
    zmq::message_t frame;
    while (pair_.recv(frame, zmq::recv_flags::dontwait)) {
      // Each event is two frames: [event id, value] then the peer's endpoint.
      if (frame.more()) ++count_;
    }
    return count_;
  }

 private:
  zmq::socket_t pair_;
  int count_{0};
};

class TempDir {
 public:
  TempDir() {
    std::string pattern = (fs::temp_directory_path() / "teleop_zmq_link_XXXXXX").string();
    if (::mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
    path_ = pattern;
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  [[nodiscard]] const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

void write_text(const fs::path& path, const std::string& text, fs::perms perms) {
  {
    std::ofstream out(path);
    out << text;
  }
  fs::permissions(path, perms);
}

mode_t mode_of(const fs::path& path) {
  struct stat st {};
  EXPECT_EQ(::stat(path.c_str(), &st), 0);
  return st.st_mode & 07777;
}

// --- policy -----------------------------------------------------------------------------

TEST(LoopbackEndpoint, OnlyAddressesThatCannotLeaveTheMachine) {
  EXPECT_TRUE(is_loopback_endpoint("tcp://127.0.0.1:5555"));
  EXPECT_TRUE(is_loopback_endpoint("tcp://127.1.2.3:5555"));
  EXPECT_TRUE(is_loopback_endpoint("tcp://127.0.0.1:*"));
  EXPECT_TRUE(is_loopback_endpoint("tcp://localhost:5555"));
  EXPECT_TRUE(is_loopback_endpoint("tcp://[::1]:5555"));
  EXPECT_TRUE(is_loopback_endpoint("ipc:///tmp/teleop.sock"));
  EXPECT_TRUE(is_loopback_endpoint("inproc://state"));

  EXPECT_FALSE(is_loopback_endpoint("tcp://*:5555"));  // binds every interface
  EXPECT_FALSE(is_loopback_endpoint("tcp://0.0.0.0:5555"));
  EXPECT_FALSE(is_loopback_endpoint("tcp://10.1.2.3:5555"));
  EXPECT_FALSE(is_loopback_endpoint("tcp://128.0.0.1:5555"));
  EXPECT_FALSE(is_loopback_endpoint("tcp://127.0.0.256:5555"));
  EXPECT_FALSE(is_loopback_endpoint("tcp://127.1:5555"));  // shorthand: not worth the doubt
  EXPECT_FALSE(is_loopback_endpoint("tcp://127.0.0.1.evil.example:5555"));
  EXPECT_FALSE(is_loopback_endpoint("tcp://localhost.example:5555"));
  EXPECT_FALSE(is_loopback_endpoint("tcp://[::]:5555"));
  EXPECT_FALSE(is_loopback_endpoint("tcp://lo:5555"));  // an interface name
  EXPECT_FALSE(is_loopback_endpoint("tcp://10.0.0.1:5555;127.0.0.1:5556"));
  EXPECT_FALSE(is_loopback_endpoint("tcp://127.0.0.1"));
  EXPECT_FALSE(is_loopback_endpoint("udp://127.0.0.1:5555"));
  EXPECT_FALSE(is_loopback_endpoint(""));
}

TEST(LinkPolicy, PlaintextOffLoopbackIsRefusedNamingTheEndpoint) {
  zmq::context_t ctx;
  const LinkSecurity none{};
  const std::string sub_error = message_of<std::invalid_argument>(
      [&] { (void)make_state_subscriber(ctx, "tcp://10.1.2.3:5555", none); });
  EXPECT_NE(sub_error.find("tcp://10.1.2.3:5555 is not a loopback endpoint: CURVE keys are "
                           "required (set master.node.secret_key_file / "
                           "slave.node.secret_key_file and the public keys in security) or "
                           "security.insecure: true to send plaintext"),
            std::string::npos)
      << sub_error;
  // Refused before binding: nothing listens on every interface, even briefly.
  const std::string pub_error = message_of<std::invalid_argument>(
      [&] { (void)make_state_publisher(ctx, "tcp://*:5555", none); });
  EXPECT_NE(pub_error.find("tcp://*:5555 is not a loopback endpoint"), std::string::npos)
      << pub_error;
  const std::string cmd_error = message_of<std::invalid_argument>(
      [&] { (void)make_command_server(ctx, "tcp://0.0.0.0:5555", none); });
  EXPECT_NE(cmd_error.find("tcp://0.0.0.0:5555 is not a loopback endpoint"), std::string::npos)
      << cmd_error;
}

TEST(LinkPolicy, InsecureAllowsPlaintextOffLoopback) {
  LinkSecurity insecure{};
  insecure.insecure = true;
  EXPECT_EQ(choose_mechanism("tcp://*:5555", LinkRole::kServer, insecure),
            LinkMechanism::kPlaintext);
  EXPECT_EQ(choose_mechanism("tcp://10.1.2.3:5555", LinkRole::kClient, insecure),
            LinkMechanism::kPlaintext);
  // Connecting is asynchronous: the socket is made even though nothing answers there.
  zmq::context_t ctx;
  EXPECT_NO_THROW((void)make_state_subscriber(ctx, "tcp://10.1.2.3:5555", insecure));
  // Loopback needs no keys and no flag.
  EXPECT_EQ(choose_mechanism("tcp://127.0.0.1:5555", LinkRole::kServer, LinkSecurity{}),
            LinkMechanism::kPlaintext);
}

TEST(LinkPolicy, GivenKeysAreUsedEvenOnLoopbackOrWithInsecure) {
  const Peers peers;
  LinkSecurity server = peers.server_security();
  server.insecure = true;
  EXPECT_EQ(choose_mechanism("tcp://127.0.0.1:5555", LinkRole::kServer, server),
            LinkMechanism::kCurve);
  EXPECT_EQ(choose_mechanism("tcp://10.1.2.3:5555", LinkRole::kClient,
                             peers.client_security(peers.good, peers.server.public_z85)),
            LinkMechanism::kCurve);
}

TEST(LinkPolicy, IncompleteKeysAreAMistakeEvenOnLoopback) {
  const Peers peers;
  const std::string endpoint = "tcp://127.0.0.1:5555";
  const LinkSecurity no_allowlist{false, peers.server, {}, std::nullopt};
  EXPECT_NE(message_of<std::invalid_argument>([&] {
              (void)choose_mechanism(endpoint, LinkRole::kServer, no_allowlist);
            }).find("no allowed client keys"),
            std::string::npos);
  const LinkSecurity no_server_key{false, peers.good, {}, std::nullopt};
  EXPECT_NE(message_of<std::invalid_argument>([&] {
              (void)choose_mechanism(endpoint, LinkRole::kClient, no_server_key);
            }).find("no server public key"),
            std::string::npos);
  const LinkSecurity bad_allowed{false, peers.server, {"not-a-key"}, std::nullopt};
  EXPECT_NE(message_of<std::invalid_argument>([&] {
              (void)choose_mechanism(endpoint, LinkRole::kServer, bad_allowed);
            }).find("allowed client key #1 is not a CURVE key"),
            std::string::npos);
  CurveKeyPair mixed = peers.good;
  mixed.public_z85 = peers.stranger.public_z85;
  const LinkSecurity mixed_pair{false, mixed, {}, peers.server.public_z85};
  EXPECT_NE(message_of<std::invalid_argument>([&] {
              (void)choose_mechanism(endpoint, LinkRole::kClient, mixed_pair);
            }).find("own public key does not belong to own secret key"),
            std::string::npos);
}

TEST(LinkPolicy, CurveServerNeedsAZapHandler) {
  // Without a handler libzmq would accept any client key: the allowlist would be a lie.
  zmq::context_t ctx;
  const Peers peers;
  const std::string error = message_of<std::invalid_argument>(
      [&] { (void)make_state_publisher(ctx, kAnyLoopbackPort, peers.server_security()); });
  EXPECT_NE(error.find("tcp://127.0.0.1:*: a CURVE server needs a ZapHandler"), std::string::npos)
      << error;
}

TEST(ZapHandlerTest, OnePerContext) {
  zmq::context_t ctx;
  const ZapHandler first(ctx);
  EXPECT_EQ(ZapHandler::serving(ctx), &first);
  EXPECT_THROW(ZapHandler second(ctx), std::runtime_error);
  zmq::context_t other;
  EXPECT_EQ(ZapHandler::serving(other), nullptr);
}

// --- CURVE on real sockets --------------------------------------------------------------

TEST(CurveLink, AllowlistedClientReceives) {
  zmq::context_t ctx;
  ZapHandler zap(ctx);
  const Peers peers;
  zmq::socket_t publisher = make_state_publisher(ctx, kAnyLoopbackPort, peers.server_security());
  const std::string endpoint = bound_endpoint(publisher);
  zmq::socket_t subscriber = make_state_subscriber(
      ctx, endpoint, peers.client_security(peers.good, peers.server.public_z85));
  int next = 0;
  ASSERT_TRUE(pump_until_received(publisher, subscriber, next, 0).has_value());
  EXPECT_EQ(zap.accepted_count(), 1u);
  EXPECT_EQ(zap.refused_count(), 0u);
}

TEST(CurveLink, UnknownClientKeyIsRefusedCountedAndNamed) {
  zmq::context_t ctx;
  ZapHandler zap(ctx);
  const Peers peers;
  zmq::socket_t publisher = make_state_publisher(ctx, kAnyLoopbackPort, peers.server_security());
  const std::string endpoint = bound_endpoint(publisher);
  zmq::socket_t stranger = make_state_subscriber(
      ctx, endpoint, peers.client_security(peers.stranger, peers.server.public_z85));
  zmq::socket_t good = make_state_subscriber(
      ctx, endpoint, peers.client_security(peers.good, peers.server.public_z85));

  // Barrier: the refusal has happened, and the good client got a message sent after it.
  int next = 0;
  std::optional<int> sent_after_refusal;
  std::optional<int> received;
  const auto deadline = Clock::now() + kDeadline;
  while (Clock::now() < deadline &&
         !(received && sent_after_refusal && *received >= *sent_after_refusal)) {
    if (!sent_after_refusal && zap.refused_count() > 0) sent_after_refusal = next;
    send_text(publisher, std::to_string(next++));
    if (const auto got = recv_latest(good, kPollStep)) received = std::stoi(*got);
  }
  ASSERT_TRUE(sent_after_refusal.has_value()) << "the stranger was never refused";
  ASSERT_TRUE(received.has_value() && *received >= *sent_after_refusal)
      << "the allowlisted client received nothing after the refusal";

  EXPECT_FALSE(recv_latest(stranger, milliseconds{0}).has_value());
  EXPECT_EQ(zap.refused_count(), 1u);
  EXPECT_EQ(zap.accepted_count(), 1u);
  const std::vector<ZapRefusal> refusals = zap.recent_refusals();
  ASSERT_EQ(refusals.size(), 1u);
  EXPECT_EQ(refusals[0].client_key_z85, peers.stranger.public_z85);
  EXPECT_EQ(refusals[0].peer_address, "127.0.0.1");
  EXPECT_EQ(refusals[0].domain_label, kAnyLoopbackPort);
  EXPECT_NE(refusals[0].reason.find("allowed_client_keys"), std::string::npos);
}

TEST(CurveLink, ClientWithWrongServerKeyReceivesNothing) {
  zmq::context_t ctx;
  ZapHandler zap(ctx);
  const Peers peers;
  // The client's own key is allowlisted: only the server key it trusts is wrong (a spoofed
  // or misconfigured server), so the handshake itself must fail.
  LinkSecurity server_security = peers.server_security();
  server_security.allowed_client_keys.push_back(peers.stranger.public_z85);
  zmq::socket_t publisher = make_state_publisher(ctx, kAnyLoopbackPort, server_security);
  HandshakeFailures failures(ctx, publisher);
  const std::string endpoint = bound_endpoint(publisher);
  const CurveKeyPair impostor = generate_curve_keypair();
  zmq::socket_t misled = make_state_subscriber(
      ctx, endpoint, peers.client_security(peers.stranger, impostor.public_z85));

  const auto deadline = Clock::now() + kDeadline;
  while (Clock::now() < deadline && failures.poll(kPollStep) == 0) {
  }
  ASSERT_GT(failures.poll(milliseconds{0}), 0) << "the server never rejected the handshake";

  zmq::socket_t good = make_state_subscriber(
      ctx, endpoint, peers.client_security(peers.good, peers.server.public_z85));
  int next = 0;
  ASSERT_TRUE(pump_until_received(publisher, good, next, 0).has_value());
  EXPECT_FALSE(recv_latest(misled, milliseconds{0}).has_value());
  // Rejected before ZAP: it never got as far as presenting its (allowed) key.
  EXPECT_EQ(zap.refused_count(), 0u);
  EXPECT_EQ(zap.accepted_count(), 1u);
}

TEST(CurveLink, ServerNotSetUpThroughThePolicyIsRefused) {
  // Fail closed: a CURVE socket configured by hand has no registered allowlist.
  zmq::context_t ctx;
  ZapHandler zap(ctx);
  const Peers peers;
  zmq::socket_t publisher(ctx, zmq::socket_type::pub);
  publisher.set(zmq::sockopt::linger, 0);
  publisher.set(zmq::sockopt::curve_server, true);
  publisher.set(zmq::sockopt::curve_secretkey, peers.server.secret_z85);
  publisher.bind(kAnyLoopbackPort);
  zmq::socket_t subscriber = make_state_subscriber(
      ctx, bound_endpoint(publisher), peers.client_security(peers.good, peers.server.public_z85));
  const auto deadline = Clock::now() + kDeadline;
  int next = 0;
  while (Clock::now() < deadline && zap.refused_count() == 0) {
    send_text(publisher, std::to_string(next++));
    EXPECT_FALSE(recv_latest(subscriber, kPollStep).has_value());
  }
  ASSERT_GE(zap.refused_count(), 1u);
  EXPECT_NE(zap.recent_refusals().at(0).reason.find("unknown ZAP domain"), std::string::npos);
  EXPECT_EQ(zap.accepted_count(), 0u);
}

TEST(CurveLink, CommandRoundTripAndATimedOutRequestDoesNotWedgeTheClient) {
  zmq::context_t ctx;
  ZapHandler zap(ctx);
  const Peers peers;
  zmq::socket_t server = make_command_server(ctx, kAnyLoopbackPort, peers.server_security());
  const std::string endpoint = bound_endpoint(server);
  zmq::socket_t client =
      make_command_client(ctx, endpoint, peers.client_security(peers.good, peers.server.public_z85),
                          std::chrono::duration_cast<milliseconds>(kDeadline));

  std::promise<void> release_late_reply;
  std::future<void> late_reply_released = release_late_reply.get_future();
  // The server answers each request with "re:" + request, holding its answer to "late"
  // until the client has given up on it.
  std::thread server_thread([&server, &late_reply_released] {
    for (int i = 0; i < 3; ++i) {
      zmq::pollitem_t item{server.handle(), 0, ZMQ_POLLIN, 0};
      if (zmq::poll(&item, 1, kDeadline) == 0) return;
      zmq::message_t request;
      if (!server.recv(request, zmq::recv_flags::none)) return;
      if (request.to_string() == "late") late_reply_released.wait();
      (void)server.send(zmq::buffer("re:" + request.to_string()), zmq::send_flags::none);
    }
  });

  EXPECT_EQ(request_reply(client, "first"), std::optional<std::string>("re:first"));
  client.set(zmq::sockopt::rcvtimeo, 50);
  EXPECT_EQ(request_reply(client, "late"), std::nullopt);
  release_late_reply.set_value();
  client.set(zmq::sockopt::rcvtimeo, static_cast<int>(milliseconds{kDeadline}.count()));
  // A plain REQ would refuse to send here (EFSM); the late "re:late" must be discarded.
  EXPECT_EQ(request_reply(client, "next"), std::optional<std::string>("re:next"));
  server_thread.join();
  EXPECT_EQ(zap.accepted_count(), 1u);
}

TEST(CommandClient, TimeoutMustBePositive) {
  zmq::context_t ctx;
  EXPECT_THROW((void)make_command_client(ctx, "tcp://127.0.0.1:5555", {}, milliseconds{0}),
               std::invalid_argument);
}

// --- latest value -----------------------------------------------------------------------

TEST(LatestValue, BurstDeliversTheNewestNotABacklog) {
  zmq::context_t ctx;
  zmq::socket_t publisher = make_state_publisher(ctx, kAnyLoopbackPort, {});
  zmq::socket_t subscriber = make_state_subscriber(ctx, bound_endpoint(publisher), {});
  // A SUB sees only what is published after its subscription arrives: wait for that first.
  int probe = 0;
  ASSERT_TRUE(pump_until_received(publisher, subscriber, probe, 0).has_value());

  // (Appended, not "#" + std::to_string(i): GCC 12's -O3 -Wrestrict misreads that one.)
  for (int i = 0; i < 1000; ++i) send_text(publisher, std::string("#").append(std::to_string(i)));

  // libzmq's conflated slot can hold the newest message back until the next send (its double
  // buffer skips a swap while the reader holds the lock), so, like a node re-publishing its
  // state every period, the publisher repeats its latest state while nothing arrives.
  std::vector<int> seen;
  const auto deadline = Clock::now() + kDeadline;
  while (Clock::now() < deadline && (seen.empty() || seen.back() != 999)) {
    const auto got = recv_latest(subscriber, kPollStep);
    if (!got) {
      send_text(publisher, "#999");
      continue;
    }
    if (got->front() != '#') continue;  // a late probe: older than the burst
    seen.push_back(std::stoi(got->substr(1)));
  }
  ASSERT_FALSE(seen.empty());
  EXPECT_EQ(seen.back(), 999);
  for (std::size_t i = 1; i < seen.size(); ++i) EXPECT_GT(seen[i], seen[i - 1]);
  // A queue would hand over all 1000 in order; the publisher's conflation keeps one slot, so
  // only a handful ever cross the wire, and recv_latest() returns the newest of what arrived.
  EXPECT_LT(seen.size(), 100u);
  // Nothing older waits behind the newest (a repeat of it may).
  if (const auto after = recv_latest(subscriber, milliseconds{0})) {
    EXPECT_EQ(*after, "#999");
  }
  EXPECT_TRUE(publisher.get(zmq::sockopt::conflate));
}

// A node's context: the peer link on one libzmq I/O thread, the service endpoints (commands,
// telemetry) on the other, so a stranger's traffic on those is never worked through on the
// thread carrying the link's states. Each lane is a real I/O thread: both carry messages in a
// context of kNodeIoThreads, and libzmq refuses to bind a lane a context does not have (the
// affinity is in force, not just stored).
TEST(IoLanes, TheLinkAndTheServiceEndpointsRunOnTheirOwnIoThreads) {
  zmq::context_t ctx{kNodeIoThreads};
  zmq::socket_t publisher = make_state_publisher(ctx, kAnyLoopbackPort, {}, IoLane::kPeerLink);
  zmq::socket_t subscriber =
      make_state_subscriber(ctx, bound_endpoint(publisher), {}, IoLane::kPeerLink);
  zmq::socket_t server = make_command_server(ctx, kAnyLoopbackPort, {}, IoLane::kService);
  zmq::socket_t telemetry = make_telemetry_publisher(ctx, kAnyLoopbackPort, {}, IoLane::kService);
  EXPECT_EQ(publisher.get(zmq::sockopt::affinity), 1u);
  EXPECT_EQ(subscriber.get(zmq::sockopt::affinity), 1u);
  EXPECT_EQ(server.get(zmq::sockopt::affinity), 2u);
  EXPECT_EQ(telemetry.get(zmq::sockopt::affinity), 2u);
  int probe = 0;
  EXPECT_TRUE(pump_until_received(publisher, subscriber, probe, 0).has_value());
  zmq::socket_t client = make_command_client(ctx, bound_endpoint(server), {}, milliseconds{2000});
  send_text(client, "ping");
  zmq::message_t request;
  ASSERT_TRUE(server.recv(request));
  EXPECT_EQ(request.to_string(), "ping");

  zmq::context_t one{1};
  EXPECT_THROW((void)make_command_server(one, kAnyLoopbackPort, {}, IoLane::kService), BindError);
  EXPECT_NO_THROW((void)make_command_server(one, kAnyLoopbackPort, {}, IoLane::kPeerLink));
}

TEST(LatestValue, NothingPendingTimesOutEmpty) {
  zmq::context_t ctx;
  zmq::socket_t publisher = make_state_publisher(ctx, kAnyLoopbackPort, {});
  zmq::socket_t subscriber = make_state_subscriber(ctx, bound_endpoint(publisher), {});
  EXPECT_FALSE(recv_latest(subscriber, milliseconds{0}).has_value());
  EXPECT_FALSE(recv_latest(subscriber, milliseconds{1}).has_value());
}

TEST(LatestValue, SubscriberPicksUpARestartedPublisher) {
  zmq::context_t ctx;
  std::optional<zmq::socket_t> publisher = make_state_publisher(ctx, kAnyLoopbackPort, {});
  const std::string endpoint = bound_endpoint(*publisher);
  zmq::socket_t subscriber = make_state_subscriber(ctx, endpoint, {});
  int next = 0;
  ASSERT_TRUE(pump_until_received(*publisher, subscriber, next, 0).has_value());

  publisher.reset();
  // The old listener closes asynchronously in libzmq's I/O thread: retry until the port is free.
  const auto deadline = Clock::now() + kDeadline;
  while (!publisher && Clock::now() < deadline) {
    try {
      publisher = make_state_publisher(ctx, endpoint, {});
    } catch (const zmq::error_t& e) {
      ASSERT_EQ(e.num(), EADDRINUSE) << e.what();
    }
  }
  ASSERT_TRUE(publisher.has_value()) << "could not rebind " << endpoint;
  const int first_after_restart = next;
  ASSERT_TRUE(pump_until_received(*publisher, subscriber, next, first_after_restart).has_value());
}

// --- keys -------------------------------------------------------------------------------

TEST(KeyFiles, KeygenWritesPrivateKeyFilesThatLoadBack) {
  const TempDir dir;
  const fs::path name = dir.path() / "master";
  std::ostringstream out;
  std::ostringstream err;
  ASSERT_EQ(ctl::run_keygen({name.string()}, out, err), ctl::kExitOk) << err.str();
  const fs::path key_file = dir.path() / "master.key";
  const fs::path pub_file = dir.path() / "master.pub";
  EXPECT_EQ(mode_of(key_file), 0600u);
  ASSERT_TRUE(fs::exists(pub_file));

  const CurveKeyPair loaded = load_secret_key_file(key_file);
  EXPECT_EQ(load_public_key(pub_file.string()), loaded.public_z85);
  EXPECT_EQ(load_public_key(loaded.public_z85), loaded.public_z85);
  EXPECT_NE(out.str().find("public-key = " + loaded.public_z85), std::string::npos) << out.str();
  EXPECT_EQ(curve_public_from_secret(loaded.secret_z85), loaded.public_z85);
}

// A key file whose path is 40 characters of the Z85 alphabet (a temp dir's
// "/tmp/teleop-nodes-XXXXXX/keys/master.pub" is one) is read as the file it names, not taken
// for a key: found by the two-machine walk-through, where every handshake failed in silence.
TEST(KeyFiles, AFortyCharacterPathIsReadAsTheFileItNames) {
  // mkdtemp's characters and the name's are all in the Z85 alphabet.
  std::string pattern = "/tmp/kfXXXXXX";
  ASSERT_NE(::mkdtemp(pattern.data()), nullptr);
  const fs::path dir = pattern;
  std::ostringstream out;
  std::ostringstream err;
  ASSERT_EQ(ctl::run_keygen({(dir / "m").string()}, out, err), ctl::kExitOk) << err.str();
  const CurveKeyPair loaded = load_secret_key_file(dir / "m.key");
  // A name that makes the whole path exactly 40 characters: "/tmp/kfXXXXXX/" + 22 + ".pub".
  const fs::path path = dir / (std::string(40 - dir.string().size() - 1 - 4, 'k') + ".pub");
  ASSERT_EQ(path.string().size(), 40u) << path;
  fs::copy_file(dir / "m.pub", path);
  // The path is a well-formed key in its own right: the ambiguity is real.
  EXPECT_FALSE(z85_key_problem(path.string()).has_value()) << path;
  EXPECT_EQ(load_public_key(path.string()), loaded.public_z85) << path;
  fs::remove_all(dir);
}

TEST(KeyFiles, KeygenRefusesToOverwriteWithoutForce) {
  const TempDir dir;
  const std::string name = (dir.path() / "slave").string();
  std::ostringstream out;
  std::ostringstream err;
  ASSERT_EQ(ctl::run_keygen({name}, out, err), ctl::kExitOk) << err.str();
  const std::string original = load_secret_key_file(name + ".key").public_z85;

  std::ostringstream err2;
  EXPECT_EQ(ctl::run_keygen({name}, out, err2), ctl::kExitError);
  EXPECT_NE(err2.str().find("refusing to overwrite " + name + ".key"), std::string::npos)
      << err2.str();
  EXPECT_EQ(load_secret_key_file(name + ".key").public_z85, original);

  std::ostringstream err3;
  EXPECT_EQ(ctl::run_keygen({name, "--force"}, out, err3), ctl::kExitOk) << err3.str();
  const CurveKeyPair replaced = load_secret_key_file(name + ".key");
  EXPECT_NE(replaced.public_z85, original);
  EXPECT_EQ(load_public_key(name + ".pub"), replaced.public_z85);
  EXPECT_EQ(mode_of(name + ".key"), 0600u);

  std::ostringstream err4;
  EXPECT_EQ(ctl::run_keygen({}, out, err4), ctl::kExitUsage);
  EXPECT_EQ(ctl::run_keygen({"a", "b"}, out, err4), ctl::kExitUsage);
  EXPECT_EQ(ctl::run_keygen({name, "--bogus"}, out, err4), ctl::kExitUsage);
}

TEST(KeyFiles, TamperedKeyFileIsRejectedNamingTheFile) {
  const TempDir dir;
  const CurveKeyPair mine = generate_curve_keypair();
  const CurveKeyPair other = generate_curve_keypair();
  const fs::path path = dir.path() / "tampered.key";
  write_text(
      path,
      "# edited\npublic-key = " + other.public_z85 + "\nsecret-key = " + mine.secret_z85 + "\n",
      fs::perms::owner_read | fs::perms::owner_write);
  const std::string error =
      message_of<std::runtime_error>([&] { (void)load_secret_key_file(path); });
  EXPECT_NE(error.find(path.string()), std::string::npos) << error;
  EXPECT_NE(error.find("public-key does not belong to secret-key"), std::string::npos) << error;
}

TEST(KeyFiles, SecretKeyReadableByOthersIsRefused) {
  const TempDir dir;
  const CurveKeyPair keys = generate_curve_keypair();
  const fs::path path = dir.path() / "leaky.key";
  write_text(path, "public-key = " + keys.public_z85 + "\nsecret-key = " + keys.secret_z85 + "\n",
             fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read);
  const std::string error =
      message_of<std::runtime_error>([&] { (void)load_secret_key_file(path); });
  EXPECT_NE(error.find(path.string()), std::string::npos) << error;
  EXPECT_NE(error.find("mode 0640"), std::string::npos) << error;
  EXPECT_NE(error.find("chmod 600"), std::string::npos) << error;
}

TEST(KeyFiles, MissingAndMalformedKeysAreNamed) {
  const TempDir dir;
  const fs::path missing = dir.path() / "nobody.key";
  const std::string missing_error =
      message_of<std::runtime_error>([&] { (void)load_secret_key_file(missing); });
  EXPECT_NE(missing_error.find(missing.string() + ": no such file"), std::string::npos)
      << missing_error;

  const fs::path short_key = dir.path() / "short.key";
  write_text(short_key, "secret-key = abc\n", fs::perms::owner_read | fs::perms::owner_write);
  const std::string short_error =
      message_of<std::runtime_error>([&] { (void)load_secret_key_file(short_key); });
  EXPECT_NE(short_error.find(short_key.string() + " line 1: secret-key is not a CURVE key: 3 "
                                                  "characters, expected 40"),
            std::string::npos)
      << short_error;

  const fs::path pub_only = dir.path() / "only.pub";
  write_text(pub_only, "public-key = " + generate_curve_keypair().public_z85 + "\n",
             fs::perms::owner_read | fs::perms::owner_write);
  EXPECT_NE(message_of<std::runtime_error>([&] {
              (void)load_secret_key_file(pub_only);
            }).find("has no secret-key line"),
            std::string::npos);

  // Forty characters, one of them outside the Z85 alphabet.
  const std::string not_z85 = std::string(39, 'a') + "~";
  EXPECT_NE(message_of<std::runtime_error>([&] {
              (void)load_public_key(not_z85);
            }).find("character 40 ('~') is not Z85"),
            std::string::npos);
  EXPECT_NE(message_of<std::runtime_error>([&] {
              (void)load_public_key("peer.pub");
            }).find("'peer.pub' is neither a 40-character Z85 key nor an existing key file"),
            std::string::npos);
}

}  // namespace
}  // namespace teleop::transport
