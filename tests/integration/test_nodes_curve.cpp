// Issue 4 "Security" at process level: the real teleop-master / teleop-slave on loopback with
// CURVE keys made by the real `teleopctl keygen`. The nodes link and engage; a client with an
// unlisted key gets neither telemetry nor a hearing for its commands, and the node's log names
// it; a slave holding the wrong master key never links; plaintext off loopback and a secret key
// file that is not the configured node's are refused at start. Waits are for conditions seen in
// telemetry or in the logs, bounded only against a hang.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <initializer_list>

#include "common/transport/zmq_security.hpp"
#include "tests/integration/node_harness.hpp"

namespace teleop::test {
namespace {

// One key pair written by `teleopctl keygen NAME` in `dir`.
struct Keys {
  std::filesystem::path key_file{};  // NAME.key (secret, 0600)
  std::filesystem::path pub_file{};  // NAME.pub
  std::string public_z85{};
  std::string secret_z85{};
};

// Runs teleopctl with `args`; its exit status, and its stdout+stderr in `output`.
int teleopctl(const TempDir& dir, const std::vector<std::string>& args, std::string* output) {
  static int runs = 0;
  Process p(TELEOPCTL_PATH, args, dir.path() / ("teleopctl-" + std::to_string(runs++) + ".out"));
  const int status = p.wait();
  if (output != nullptr) *output = p.log();
  return status;
}

// The real `teleopctl keygen`; the files are read back with the nodes' own loaders.
Keys keygen(const TempDir& dir, const std::string& name) {
  const std::filesystem::path stem = dir.path() / name;
  std::string out;
  const int status = teleopctl(dir, {"keygen", stem.string()}, &out);
  EXPECT_EQ(status, 0) << out;
  Keys k;
  k.key_file = stem.string() + ".key";
  k.pub_file = stem.string() + ".pub";
  const transport::CurveKeyPair pair = transport::load_secret_key_file(k.key_file);
  k.public_z85 = pair.public_z85;
  k.secret_z85 = pair.secret_z85;
  EXPECT_EQ(transport::load_public_key(k.pub_file.string()), k.public_z85);
  EXPECT_NE(out.find("public-key = " + k.public_z85), std::string::npos) << out;
  return k;
}

// A CURVE client socket of `client` talking to the node whose public key is `server_public`.
std::function<void(zmq::socket_t&)> curve_client(const Keys& client,
                                                 const std::string& server_public) {
  return [client, server_public](zmq::socket_t& s) {
    s.set(zmq::sockopt::curve_serverkey, server_public);
    s.set(zmq::sockopt::curve_publickey, client.public_z85);
    s.set(zmq::sockopt::curve_secretkey, client.secret_z85);
  };
}

std::string quoted(const std::string& s) { return "\"" + s + "\""; }

std::string security_section(const std::string& master_public, const std::string& slave_public,
                             const std::vector<std::string>& clients) {
  std::string s = "security { master_public_key: " + quoted(master_public) +
                  " slave_public_key: " + quoted(slave_public);
  for (const std::string& c : clients) s += " client_public_keys: " + quoted(c);
  return s + " }\n";
}

std::string secret_key(const std::filesystem::path& file) {
  return "secret_key_file: " + quoted(file.string());
}

// The paper's paddles at 1 kHz (as test_nodes), with extra text in each node section and at the
// end of the file.
std::string paddles_config(const Ports& p, const std::string& master_node_extra,
                           const std::string& slave_node_extra, const std::string& tail) {
  return "sample_rate_hz: 1000\n"
         "master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 } " +
         node_section(p, true, master_node_extra) +
         " }\n"
         "slave { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 } " +
         node_section(p, false, slave_node_extra) +
         " }\n"
         "gains { kpm: 600 kps: 600 kdm: 2 kds: 2 }\n"
         "velocity_filter { cutoff_hz: 200 }\n"
         "human { fixed { mass_kg: 0.012 damping_Ns_per_m: 0.76 stiffness_N_per_m: 70 } }\n"
         "scene { duration_s: 3 seed: 1 human_force { constant { force_N: 1 } } }\n"
         "link { engage_ramp_ms: 20 }\n" +
         tail;
}

// Master, slave and console keys, and the configuration every node of a CURVE run reads.
struct CurveSetup {
  explicit CurveSetup(const TempDir& dir)
      : master(keygen(dir, "master")),
        slave(keygen(dir, "slave")),
        console(keygen(dir, "console")) {}
  [[nodiscard]] std::string config(const Ports& p) const {
    return config_with_master_key(p, master.public_z85);
  }
  // As config(), but every node takes `master_public` as the master's public key.
  [[nodiscard]] std::string config_with_master_key(const Ports& p,
                                                   const std::string& master_public) const {
    return paddles_config(p, secret_key(master.key_file), secret_key(slave.key_file),
                          security_section(master_public, slave.public_z85, {console.public_z85}));
  }
  Keys master;
  Keys slave;
  Keys console;
};

bool linked(const v1::Telemetry& t) { return t.link().accepted() > 0; }

// True when one line of `log` contains every one of `parts`.
bool has_line(const std::string& log, std::initializer_list<std::string> parts) {
  std::istringstream in(log);
  std::string line;
  while (std::getline(in, line)) {
    bool all = true;
    for (const std::string& part : parts) all = all && line.find(part) != std::string::npos;
    if (all) return true;
  }
  return false;
}

// The spdlog text of zap_handler.cpp for a client key missing from the allowlist.
constexpr const char* kNotAllowed = "client key is not in allowed_client_keys";

std::string refused(const Keys& k) { return "ZAP: refused client " + k.public_z85; }
std::string accepted(const Keys& k) { return "ZAP: accepted CURVE client " + k.public_z85; }

// Arm and engage both nodes with the console's key.
void engage(zmq::context_t& ctx, const Ports& p, const CurveSetup& keys) {
  for (const auto kind : {v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
    for (const auto& [port, server] :
         {std::pair{p.master_command, &keys.master}, std::pair{p.slave_command, &keys.slave}}) {
      const auto r =
          send_command(ctx, tcp(port), kind, curve_client(keys.console, server->public_z85));
      ASSERT_TRUE(r.has_value()) << "no reply from " << port;
      ASSERT_TRUE(r->ok()) << r->message();
    }
  }
}

struct CurveNodes {
  CurveNodes(const TempDir& dir, const std::string& master_config,
             const std::string& slave_config) {
    const auto mc = dir.write("master.textproto", master_config);
    const auto sc = dir.write("slave.textproto", slave_config);
    master = std::make_unique<Process>(MASTER_BIN, std::vector<std::string>{mc.string()},
                                       dir.path() / "master.log");
    slave = std::make_unique<Process>(SLAVE_BIN, std::vector<std::string>{sc.string()},
                                      dir.path() / "slave.log");
  }
  std::unique_ptr<Process> master;
  std::unique_ptr<Process> slave;
};

TEST(NodesCurve, KeysFromTeleopctlKeygenLinkAndEngageOverCurveWithTheConsolesKey) {
  TempDir dir;
  const CurveSetup keys(dir);
  // keygen's secret files are private: the nodes refuse anything looser.
  for (const Keys* k : {&keys.master, &keys.slave, &keys.console}) {
    struct stat st {};
    ASSERT_EQ(::stat(k->key_file.c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 0777, 0600u) << k->key_file;
  }
  Ports ports;
  const std::string config = keys.config(ports);
  CurveNodes nodes(dir, config, config);
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.master_telemetry),
                  curve_client(keys.console, keys.master.public_z85));
  TelemetryTap st(ctx, tcp(ports.slave_telemetry),
                  curve_client(keys.console, keys.slave.public_z85));
  ASSERT_TRUE(mt.wait_for(linked)) << nodes.master->log();
  ASSERT_TRUE(st.wait_for(linked)) << nodes.slave->log();
  engage(ctx, ports, keys);
  ASSERT_TRUE(mt.wait_for_mode(v1::ENGAGED)) << nodes.master->log();
  ASSERT_TRUE(st.wait_for_mode(v1::ENGAGED)) << nodes.slave->log();

  // The operator's path: teleopctl node with the console's key file and the node's .pub.
  for (const auto& [port, server, role] : {std::tuple{ports.master_command, &keys.master, "master"},
                                           std::tuple{ports.slave_command, &keys.slave, "slave"}}) {
    std::string out;
    EXPECT_EQ(teleopctl(dir,
                        {"node", "127.0.0.1:" + std::to_string(port), "status", "--key",
                         keys.console.key_file.string(), "--server-key", server->pub_file.string()},
                        &out),
              0)
        << out;
    EXPECT_NE(
        out.find(std::string(role) + " tcp://127.0.0.1:" + std::to_string(port) + ": engaged"),
        std::string::npos)
        << out;
  }

  // Every connection went through the allowlist: each node's state publisher accepted its
  // peer's key, its telemetry and command endpoints the console's; nothing was refused.
  const std::string mlog = nodes.master->log();
  const std::string slog = nodes.slave->log();
  EXPECT_TRUE(has_line(mlog, {accepted(keys.slave), tcp(ports.master_state)})) << mlog;
  EXPECT_TRUE(has_line(slog, {accepted(keys.master), tcp(ports.slave_state)})) << slog;
  EXPECT_TRUE(has_line(mlog, {accepted(keys.console), tcp(ports.master_telemetry)})) << mlog;
  EXPECT_TRUE(has_line(mlog, {accepted(keys.console), tcp(ports.master_command)})) << mlog;
  EXPECT_TRUE(has_line(slog, {accepted(keys.console), tcp(ports.slave_command)})) << slog;
  EXPECT_EQ(mlog.find("ZAP: refused"), std::string::npos) << mlog;
  EXPECT_EQ(slog.find("ZAP: refused"), std::string::npos) << slog;
  const v1::LinkStats l = mt.last()->link();
  EXPECT_EQ(l.rejected_malformed() + l.rejected_wrong_role() + l.rejected_wrong_session(), 0u);
}

TEST(NodesCurve, UnlistedKeyGetsNoTelemetryAndNoHearingForCommandsAndTheLogNamesIt) {
  TempDir dir;
  const CurveSetup keys(dir);
  const Keys intruder = keygen(dir, "intruder");  // a valid pair, in no configuration
  Ports ports;
  const std::string config = keys.config(ports);
  CurveNodes nodes(dir, config, config);
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.master_telemetry),
                  curve_client(keys.console, keys.master.public_z85));
  ASSERT_TRUE(mt.wait_for(linked)) << nodes.master->log();
  engage(ctx, ports, keys);
  ASSERT_TRUE(mt.wait_for_mode(v1::ENGAGED)) << nodes.master->log();

  // Telemetry: the intruder knows the master's public key (it is not a secret) but is not
  // listed; a plaintext subscriber does not even speak CURVE. Same endpoint as the console.
  TelemetryTap refused_tap(ctx, tcp(ports.master_telemetry),
                           curve_client(intruder, keys.master.public_z85));
  TelemetryTap plaintext_tap(ctx, tcp(ports.master_telemetry));
  ASSERT_TRUE(mt.wait_for([&](const v1::Telemetry&) {
    return has_line(nodes.master->log(),
                    {refused(intruder), tcp(ports.master_telemetry), kNotAllowed});
  })) << nodes.master->log();
  // Barrier: the allowed subscriber on the same endpoint keeps receiving.
  const std::size_t seen = mt.messages();
  ASSERT_TRUE(mt.wait_for([&](const v1::Telemetry&) { return mt.messages() >= seen + 50; }));
  EXPECT_EQ(refused_tap.messages(), 0u);
  EXPECT_EQ(plaintext_tap.messages(), 0u);

  // Commands: the intruder's disengage gets no reply and changes nothing.
  const std::size_t before = mt.cycles().size();
  std::string out;
  EXPECT_EQ(teleopctl(dir,
                      {"node", "127.0.0.1:" + std::to_string(ports.master_command), "disengage",
                       "--key", intruder.key_file.string(), "--server-key",
                       keys.master.pub_file.string(), "--timeout-ms", "1000"},
                      &out),
            4)
      << out;
  EXPECT_NE(out.find("no reply"), std::string::npos) << out;
  ASSERT_TRUE(mt.wait_for([&](const v1::Telemetry&) {
    return has_line(nodes.master->log(),
                    {refused(intruder), tcp(ports.master_command), kNotAllowed});
  })) << nodes.master->log();
  const std::size_t after = mt.cycles().size();
  ASSERT_TRUE(mt.wait_for([&](const v1::Telemetry&) { return mt.cycles().size() > after + 100; }));
  const auto c = mt.cycles();
  for (std::size_t i = before; i < c.size(); ++i) ASSERT_EQ(c[i].mode(), v1::ENGAGED) << i;
  EXPECT_EQ(nodes.master->log().find("command DISENGAGE"), std::string::npos)
      << nodes.master->log();
  // Counted in the master's own telemetry: at least the intruder's two refused handshakes
  // (telemetry and command endpoints), and the plaintext subscriber's failed one besides.
  EXPECT_TRUE(mt.wait_for([](const v1::Telemetry& t) {
    return t.link().handshakes_refused_auth() >= 2 &&
           t.link().handshakes_failed() >= t.link().handshakes_refused_auth() + 1;
  })) << mt.last()->link().DebugString();

  // The same command with the console's key is heard: the refusal was the key, nothing else.
  EXPECT_EQ(
      teleopctl(dir,
                {"node", "127.0.0.1:" + std::to_string(ports.master_command), "disengage", "--key",
                 keys.console.key_file.string(), "--server-key", keys.master.pub_file.string()},
                &out),
      0)
      << out;
  EXPECT_TRUE(mt.wait_for([](const v1::Telemetry& t) { return t.mode() != v1::ENGAGED; }))
      << nodes.master->log();
}

TEST(NodesCurve, SlaveHoldingTheWrongMasterPublicKeyNeverLinks) {
  TempDir dir;
  const CurveSetup keys(dir);
  Ports ports;
  // The slave's file names the console's key as the master's: it neither trusts the real
  // master as a client nor can it complete a handshake with the real master as a server.
  CurveNodes nodes(dir, keys.config(ports),
                   keys.config_with_master_key(ports, keys.console.public_z85));
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.master_telemetry),
                  curve_client(keys.console, keys.master.public_z85));
  TelemetryTap st(ctx, tcp(ports.slave_telemetry),
                  curve_client(keys.console, keys.slave.public_z85));
  // The master tried the slave's state endpoint and was refused there, by key.
  ASSERT_TRUE(st.wait_for([&](const v1::Telemetry&) {
    return has_line(nodes.slave->log(),
                    {refused(keys.master), tcp(ports.slave_state), kNotAllowed});
  })) << nodes.slave->log();
  // A second of both loops: a correctly keyed pair links within milliseconds, and the slave's
  // subscriber retries at least every 100 ms meanwhile.
  ASSERT_TRUE(st.wait_for([](const v1::Telemetry& t) { return t.loop().cycles() >= 1000; }));
  ASSERT_TRUE(mt.wait_for([](const v1::Telemetry& t) { return t.loop().cycles() >= 1000; }));
  const std::size_t m = mt.messages();
  const std::size_t s = st.messages();
  ASSERT_TRUE(mt.wait_for([&](const v1::Telemetry&) { return mt.messages() > m; }));
  ASSERT_TRUE(st.wait_for([&](const v1::Telemetry&) { return st.messages() > s; }));
  for (const TelemetryTap* tap : {&mt, &st}) {
    const v1::LinkStats l = tap->last()->link();
    EXPECT_EQ(l.accepted(), 0u);
    EXPECT_EQ(l.peer_session_id(), 0u);
    EXPECT_EQ(l.rejected_malformed() + l.rejected_wrong_role() + l.rejected_wrong_session(), 0u);
  }
  // The master never saw the slave's key: its handshake failed before the allowlist.
  EXPECT_FALSE(has_line(nodes.master->log(), {accepted(keys.slave)})) << nodes.master->log();
  EXPECT_EQ(nodes.slave->log().find("peer master session"), std::string::npos);
  EXPECT_EQ(nodes.master->log().find("peer slave session"), std::string::npos);
  // Both are still running and commandable by the console.
  const auto r = send_command(ctx, tcp(ports.slave_command), v1::NodeCommand::STATUS,
                              curve_client(keys.console, keys.slave.public_z85));
  ASSERT_TRUE(r.has_value());
  EXPECT_TRUE(r->ok());
}

// Starts teleop-master on `config` and returns its exit status and output.
int run_master(const TempDir& dir, const std::string& name, const std::string& config,
               std::string* output) {
  const auto file = dir.write(name + ".textproto", config);
  Process p(MASTER_BIN, {file.string()}, dir.path() / (name + ".log"));
  const int status = p.wait();
  *output = p.log();
  return status;
}

TEST(NodesCurve, PlaintextOffLoopbackIsRefusedAtStartNamingTheEndpointBeforeAnyBind) {
  TempDir dir;
  Ports ports;
  const std::string network = "tcp://10.255.255.1:5560";  // no interface has it
  auto config = [&](const std::string& state_endpoint, const std::string& tail) {
    std::string c = paddles_config(ports, "", "", tail);
    const std::string loopback = "state_endpoint: \"" + tcp(ports.master_state) + "\"";
    c.replace(c.find(loopback), loopback.size(), "state_endpoint: \"" + state_endpoint + "\"");
    return c;
  };
  std::string out;
  EXPECT_EQ(run_master(dir, "network", config(network, ""), &out), 1) << out;
  EXPECT_TRUE(has_line(
      out, {"teleop-master: ", network, "is not a loopback endpoint: CURVE keys are required"}))
      << out;
  // Decided before binding: a bind of that address would have failed with the kernel's error.
  EXPECT_EQ(out.find("Cannot assign requested address"), std::string::npos) << out;
  EXPECT_EQ(out.find("session"), std::string::npos) << out;

  // Every interface is a network too, although binding it would succeed.
  const std::string any = "tcp://*:" + std::to_string(ports.master_state);
  EXPECT_EQ(run_master(dir, "any", config(any, ""), &out), 1) << out;
  EXPECT_TRUE(has_line(out, {any, "is not a loopback endpoint: CURVE keys are required"})) << out;

  // The contrast: with insecure: true the policy lets it through and the bind itself fails.
  EXPECT_EQ(run_master(dir, "insecure", config(network, "security { insecure: true }\n"), &out), 1)
      << out;
  EXPECT_EQ(out.find("CURVE keys are required"), std::string::npos) << out;
  EXPECT_NE(out.find("Cannot assign requested address"), std::string::npos) << out;
}

TEST(NodesCurve, SecretKeyFileOfAnotherNodeIsRefusedAtStartNamingTheFile) {
  TempDir dir;
  const CurveSetup keys(dir);
  Ports ports;
  // The master is pointed at the slave's secret key; security names the real master key.
  const std::string config = paddles_config(
      ports, secret_key(keys.slave.key_file), secret_key(keys.slave.key_file),
      security_section(keys.master.public_z85, keys.slave.public_z85, {keys.console.public_z85}));
  std::string out;
  EXPECT_EQ(run_master(dir, "mixed", config, &out), 1) << out;
  EXPECT_TRUE(has_line(out, {"teleop-master: secret key file " + keys.slave.key_file.string(),
                             "does not belong to the public key configured for this node"}))
      << out;
  EXPECT_EQ(out.find("session"), std::string::npos) << out;
}

}  // namespace
}  // namespace teleop::test
