// Writes the seed corpora (fuzz/corpus/<target>/) and dictionaries (fuzz/dict/) from the
// project's own encoders: valid inputs in each harness's format (fuzz/harness/*_harness.cpp),
// plus a few near misses (bad CRC, NaN, wrong role, cut short) so every rejection path starts
// covered. The configuration seeds are the shipped examples, copied by scripts/fuzz.sh --seeds;
// the simulated session file comes from `teleopctl simulate` (see scripts/fuzz.sh).
//
//   fuzz_make_seeds FUZZ_DIR
#include <google/protobuf/descriptor.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "common/device/usb_protocol.hpp"
#include "common/record/mcap_writer.hpp"
#include "common/transport/node_state_codec.hpp"
#include "teleop/v1/config.pb.h"
#include "teleop/v1/node_state.pb.h"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace {

namespace fs = std::filesystem;
namespace transport = teleop::transport;
namespace usb = teleop::device::usb;
namespace v1 = teleop::v1;

fs::path g_root;

void write(const std::string& target, const std::string& name, std::string_view bytes) {
  const fs::path dir = g_root / "corpus" / target;
  fs::create_directories(dir);
  std::ofstream out(dir / name, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) throw std::runtime_error("cannot write " + (dir / name).string());
}

// ---- node_state: [u8 control][u16 length][bytes] frames ----

transport::NodeStateRecord state(transport::Role role, std::uint64_t session, std::uint64_t seq) {
  transport::NodeStateRecord r;
  r.session_id = session;
  r.sequence = seq;
  r.sample_time_ns = static_cast<std::int64_t>(seq) * 1'000'000;
  r.last_peer_sequence = seq > 1 ? seq - 1 : 0;
  r.peer_age_ns = 350'000;
  r.role = role;
  r.mode = 4;  // ENGAGED
  r.position_m = 0.012 + 1e-4 * static_cast<double>(seq);
  r.velocity_m_per_s = -0.03;
  r.force_N = 1.5;
  r.fixture_in_contact = seq % 2 == 0;
  r.fixture_penetration_m = r.fixture_in_contact ? 0.0004 : 0.0;
  r.fixture_force_N = r.fixture_in_contact ? 1.2 : 0.0;
  r.clutched = false;
  r.fault_flags = 0;
  return r;
}

std::string frame(std::string_view bytes, std::uint8_t control = 0) {
  std::string out;
  out.push_back(static_cast<char>(control));
  out.push_back(static_cast<char>(bytes.size() & 0xFFU));
  out.push_back(static_cast<char>((bytes.size() >> 8U) & 0xFFU));
  out.append(bytes);
  return out;
}

void node_state_seeds() {
  using transport::Role;
  const std::uint64_t a = 0x5EC0'0001'D00D'F00DULL;
  const std::uint64_t b = 0x5EC0'0002'CAFE'BEEFULL;
  write("node_state", "master_one", frame(transport::encode(state(Role::kMaster, a, 1))));
  write("node_state", "slave_one", frame(transport::encode(state(Role::kSlave, b, 7))));
  // A session, a duplicate, a reorder, a restart, then a replay from the first session.
  std::string stream;
  for (const std::uint64_t seq : {1U, 2U, 3U, 5U}) {
    stream += frame(transport::encode(state(Role::kMaster, a, seq)));
  }
  stream += frame(transport::encode(state(Role::kMaster, a, 5)));
  stream += frame(transport::encode(state(Role::kMaster, a, 4)));
  stream += frame(transport::encode(state(Role::kMaster, b, 1)));
  stream += frame(transport::encode(state(Role::kMaster, a, 9)));
  write("node_state", "restart_and_replay", stream);
  // Without the CRC field, with control bit 0 asking the harness to append a valid one.
  std::string body = transport::encode(state(Role::kSlave, a, 3));
  body.resize(body.size() - 5);
  write("node_state", "crc_appended", frame(body, 1));
  // Near misses.
  std::string bad_crc = transport::encode(state(Role::kMaster, a, 2));
  bad_crc.back() = static_cast<char>(bad_crc.back() ^ 0x01);
  write("node_state", "bad_crc", frame(bad_crc));
  auto nan = state(Role::kMaster, a, 2);
  nan.force_N = std::numeric_limits<double>::quiet_NaN();
  nan.fixture_penetration_m = std::numeric_limits<double>::infinity();
  write("node_state", "non_finite", frame(transport::encode(nan)));
  write("node_state", "unknown_role", frame(transport::encode(state(Role::kUnknown, a, 2))));
  write("node_state", "zero_session", frame(transport::encode(state(Role::kSlave, 0, 2))));
  const std::string whole = transport::encode(state(Role::kSlave, b, 2));
  write("node_state", "truncated", frame(whole.substr(0, whole.size() / 2)));
}

// Issue 18: three task-space axes (the harness's three-axis receivers accept these).
transport::NodeStateRecord state3(transport::Role role, std::uint64_t session, std::uint64_t seq) {
  transport::NodeStateRecord r = state(role, session, seq);
  r.axes = 3;
  for (std::size_t j = 0; j < 3; ++j) {
    const double k = static_cast<double>(j + 1);
    r.set_axis(j, k * r.position_m, -0.01 * k, 0.5 * k);
  }
  return r;
}

// A three-axis slave state as protobuf's message, the CRC field left for the harness to append
// (control bit 0): the hostile seeds break one axis field at a time.
v1::NodeState three_axis_message(std::uint64_t seq) {
  v1::NodeState m;
  m.set_session_id(0x5EC0'0003'0A0E'5EEDULL);
  m.set_sequence(seq);
  m.set_role(v1::SLAVE);
  m.set_mode(v1::ENGAGED);
  m.set_position_m(0.01);
  m.set_velocity_m_per_s(-0.01);
  m.set_force_n(0.5);
  m.set_axes(3);
  for (int j = 1; j <= 3; ++j) {
    m.add_positions_m(0.01 * j);
    m.add_velocities_m_per_s(-0.01 * j);
    m.add_forces_n(0.5 * j);
  }
  return m;
}

void node_state_axes_seeds() {
  using transport::Role;
  const std::uint64_t a = 0x5EC0'0003'D00D'F00DULL;
  write("node_state", "axes3_master_one", frame(transport::encode(state3(Role::kMaster, a, 1))));
  write("node_state", "axes3_slave_one", frame(transport::encode(state3(Role::kSlave, a, 4))));
  // A three-axis session with a duplicate, then a one-axis peer on the same session.
  std::string stream;
  for (const std::uint64_t seq : {1U, 2U, 4U, 4U}) {
    stream += frame(transport::encode(state3(Role::kSlave, a, seq)));
  }
  stream += frame(transport::encode(state(Role::kSlave, a, 5)));
  stream += frame(transport::encode(state3(Role::kSlave, a, 6)));
  write("node_state", "axes3_session_and_one_axis_peer", stream);
  // Six axes, which every receiver of the harness rejects as the wrong count.
  transport::NodeStateRecord six = state3(Role::kMaster, a, 2);
  six.axes = 6;
  for (std::size_t j = 3; j < 6; ++j) six.set_axis(j, 0.001 * static_cast<double>(j), 0.0, 0.0);
  write("node_state", "axes6", frame(transport::encode(six)));
  auto nan = state3(Role::kSlave, a, 3);
  nan.positions_m[2] = std::numeric_limits<double>::quiet_NaN();
  nan.forces_N[1] = -std::numeric_limits<double>::infinity();
  write("node_state", "axes3_non_finite", frame(transport::encode(nan)));
  // Hostile axis fields, each otherwise valid, with the harness appending the CRC.
  write("node_state", "axes3_crc_appended", frame(three_axis_message(1).SerializeAsString(), 1));
  v1::NodeState m = three_axis_message(2);
  m.mutable_velocities_m_per_s()->RemoveLast();
  write("node_state", "axes3_lengths_differ", frame(m.SerializeAsString(), 1));
  m = three_axis_message(2);
  m.set_axes(7);
  for (int j = 4; j <= 7; ++j) {
    m.add_positions_m(0.01 * j);
    m.add_velocities_m_per_s(0.0);
    m.add_forces_n(0.0);
  }
  write("node_state", "axes7", frame(m.SerializeAsString(), 1));
  m = three_axis_message(2);
  m.set_axes(0);
  write("node_state", "axes0", frame(m.SerializeAsString(), 1));
  m = three_axis_message(2);
  m.set_axes(0xFFFFFFFFU);
  write("node_state", "axes_max_uint32", frame(m.SerializeAsString(), 1));
  m = three_axis_message(2);
  m.set_position_m(0.02);
  write("node_state", "axes3_scalar_not_axis0", frame(m.SerializeAsString(), 1));
}

// ---- commands: [u8 selector][protobuf] ----

void commands_seed(const std::string& name, std::uint8_t selector,
                   const google::protobuf::Message& m) {
  write("commands", name, std::string(1, static_cast<char>(selector)) + m.SerializeAsString());
}

void command_seeds() {
  v1::NodeCommand arm;
  arm.set_kind(v1::NodeCommand::ARM);
  commands_seed("node_arm", 0, arm);
  v1::NodeCommand retune;
  retune.set_kind(v1::NodeCommand::RETUNE);
  v1::ParameterUpdate* u = retune.mutable_update();
  u->set_change_id(3);
  u->mutable_gains()->set_kpm(600);
  u->mutable_gains()->set_kps(600);
  u->mutable_gains()->set_kdm(2);
  u->mutable_gains()->set_kds(2);
  u->set_slave_fixture_stiffness_n_per_m(1000);
  u->set_slave_fixture_position_m(0.01);
  u->set_apply_at_master_sequence(123456);
  u->set_ramp_ms(200);
  commands_seed("node_retune", 0, retune);

  v1::SupervisorRequest change;
  change.mutable_change()->set_slave_fixture_stiffness_n_per_m(2500);
  change.mutable_change()->set_dry_run(true);
  change.mutable_change()->set_requested_by("console");
  commands_seed("supervisor_change", 1, change);
  v1::SupervisorRequest status;
  status.mutable_status();
  commands_seed("supervisor_status", 1, status);
  v1::SupervisorRequest node;
  node.mutable_node_command()->set_kind(v1::NodeCommand::ESTOP);
  node.mutable_node_command()->set_target("both");
  commands_seed("supervisor_estop", 1, node);
  v1::SupervisorRequest recording;
  recording.mutable_recording()->set_record(true);
  commands_seed("supervisor_record", 1, recording);

  v1::Telemetry t;
  t.set_session_id(0x1234'5678'9ABC'DEF0ULL);
  t.set_role(v1::SLAVE);
  t.set_mode(v1::ENGAGED);
  t.set_mode_reason("engaged by command");
  t.set_sent_time_ns(5'000'000'000);
  t.mutable_loop()->set_period_s(0.001);
  t.mutable_loop()->set_cycles(5000);
  t.mutable_link()->set_accepted(4990);
  t.mutable_link()->set_rejected_stale(3);
  for (int i = 0; i < 3; ++i) {
    v1::CycleRecord* c = t.add_cycles();
    c->set_sequence(static_cast<std::uint64_t>(4998 + i));
    c->set_sample_time_ns(4'998'000'000 + i * 1'000'000);
    c->set_mode(v1::ENGAGED);
    c->set_position_m(0.01);
    c->set_force_n(0.5);
    c->set_command_n(0.4);
  }
  t.set_device("sim");
  commands_seed("telemetry", 2, t);

  v1::NodeCommandReply reply;
  reply.set_ok(true);
  reply.set_mode(v1::ARMED);
  reply.set_role(v1::MASTER);
  reply.set_message("armed");
  commands_seed("node_reply", 3, reply);
  v1::SupervisorReply sreply;
  sreply.mutable_change()->set_accepted(false);
  sreply.mutable_change()->set_reason("unstable at 6000 N/m");
  commands_seed("supervisor_reply", 4, sreply);
}

// ---- config: the shipped examples (copied by the script), plus overrides and errors ----

void config_seeds() {
  const std::string paddles_like =
      "sample_rate_hz: 1000\n"
      "master { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 } }\n"
      "slave {\n  device { mass_kg: 0.036 damping_Ns_per_m: 0.49 }\n"
      "  fixture { stiffness_N_per_m: 500 position_m: 0.01 }\n}\n"
      "gains { kpm: 600 kps: 600 kdm: 2 kds: 2 }\n";
  write("config", "minimal_with_overrides",
        paddles_like +
            "#--set\ngains.kps=800\nhuman.fixed.mass_kg=0.01\nhuman.band.force_levels_N=2,5,8\n"
            "human.none={}\nslave.fixture.stiffness_N_per_m=3000\ngains={kpm: 600 kps: 600}\n");
  // Strings: CURVE keys (40 characters of Z85), endpoints, a directory.
  write("config", "security_and_endpoints",
        paddles_like +
            "security {\n"
            "  master_public_key: \"rq:rM>}U?@Lns47E1%kR.o@n%FcmmsL/@{H8]yf7\"\n"
            "  slave_public_key: \"Yne@$w-vo<fVvi]a<NY6T1ed:M$fCG*[IaLV{hID\"\n"
            "  client_public_keys: [\"JTKVSB%%)wK0E.X)V>+}o?pNmC{O&4W4b!Ni{Lh6\"]\n"
            "}\n"
            "supervisor { record_dir: \"/var/lib/teleop\" report_endpoint: "
            "\"tcp://127.0.0.1:5570\" }\n"
            "link { peer_timeout_ms: 30 safe_ramp_ms: 10 engage_ramp_ms: 200 }\n");
  write("config", "unknown_field", paddles_like + "gains { kpx: 1 }\n");
  write("config", "syntax_error", "sample_rate_hz: 1000\nmaster { device { mass_kg: }\n");
  write("config", "non_finite", paddles_like + "velocity_filter { cutoff_hz: nan }\n");
  write("config", "set_twice", "sample_rate_hz: 1000\nsample_rate_hz: 500\n");
}

// ---- mcap: files from the project's writer, whole and cut ----

std::string read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

std::string small_mcap(const fs::path& scratch, std::size_t chunk_size, int messages) {
  {
    teleop::record::WriterOptions options;
    options.profile = "teleop";
    options.chunk_size_bytes = chunk_size;
    options.max_chunk_age = std::chrono::nanoseconds::max();
    teleop::record::McapWriter w(scratch, options);
    const std::uint16_t schema = w.add_schema({"teleop.v1.Gains", "protobuf", "\x0a\x04test"});
    const std::uint16_t with = w.add_channel({schema, "/gains", "protobuf", {{"k", "v"}}});
    const std::uint16_t without = w.add_channel({0, "/raw", "json", {}});
    for (int i = 0; i < messages; ++i) {
      // Log times out of file order now and then.
      const auto t = static_cast<std::uint64_t>(1000 + (i % 3 == 2 ? -5 : 10) * i);
      const std::string_view data =
          i % 2 == 0 ? std::string_view("\x09\0\0\0\0\0\0\xf0?", 9) : std::string_view("{}");
      if (!w.write(i % 2 == 0 ? with : without, t, data)) {
        throw std::runtime_error(w.error());
      }
    }
    if (!w.close()) throw std::runtime_error(w.error());
  }
  return read_file(scratch);
}

void mcap_seeds() {
  const fs::path scratch = fs::temp_directory_path() / "teleop_fuzz_seed.mcap";
  const std::string one_chunk = small_mcap(scratch, 1 << 20, 4);
  write("mcap", "one_chunk", one_chunk);
  const std::string chunks = small_mcap(scratch, 64, 9);
  write("mcap", "many_chunks", chunks);
  write("mcap", "cut_in_data", chunks.substr(0, chunks.size() / 2));
  write("mcap", "cut_in_summary", chunks.substr(0, chunks.size() - 40));
  std::string flipped = chunks;
  flipped[flipped.size() / 3] = static_cast<char>(flipped[flipped.size() / 3] ^ 0x40);
  write("mcap", "bit_flip", flipped);
  const std::string empty = small_mcap(scratch, 1 << 20, 0);
  write("mcap", "no_messages", empty);
  fs::remove(scratch);
}

// ---- usb: [u8 length][packet] stream ----

std::string packet(std::span<const std::uint8_t> bytes) {
  std::string out(1, static_cast<char>(bytes.size()));
  out.append(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  return out;
}

std::string command(std::uint32_t seq, std::uint8_t flags, std::int16_t dac) {
  usb::CommandPacket c;
  c.sequence = seq;
  c.flags = flags;
  c.actuator_dac = dac;
  usb::CommandBytes b{};
  if (usb::encode(c, b) != usb::PacketError::kNone) throw std::runtime_error("command");
  return packet(b);
}

std::string report(std::uint32_t seq, std::uint16_t flags, std::int16_t adc) {
  usb::ReportPacket r;
  r.sequence = seq;
  r.device_time_us = 1000ULL * seq;
  r.encoder_counts = -1234;
  r.load_cell_adc = adc;
  r.actuator_dac = 1000;
  r.flags = flags;
  r.last_command_sequence = seq > 0 ? seq - 1 : 0;
  usb::ReportBytes b{};
  if (usb::encode(r, b) != usb::PacketError::kNone) throw std::runtime_error("report");
  return packet(b);
}

void usb_seeds() {
  using usb::CommandFlags;
  // The host's startup: resync (disabled), then enabled commands with force, a duplicate, a
  // reorder, then disabled again.
  std::string session = command(100, CommandFlags::kResync, 0);
  for (std::uint32_t s = 101; s < 106; ++s) {
    session += command(s, CommandFlags::kEnable, static_cast<std::int16_t>(4000 * (s - 100)));
  }
  session += command(105, CommandFlags::kEnable, 100);
  session += command(103, CommandFlags::kEnable, 100);
  session += command(107, 0, 0);
  write("usb", "command_session", session);
  std::string reports;
  for (std::uint32_t s = 1; s < 5; ++s) reports += report(s, 0, static_cast<std::int16_t>(s * 900));
  reports += report(4, usb::ReportFlags::kEstopPressed, 0);
  reports +=
      report(0xFFFFFFFFU, usb::ReportFlags::kFault | usb::ReportFlags::kLoadCellClipped, 32767);
  write("usb", "report_stream", reports);
  // One bare packet of each type (the whole-input decode), and an oversized one.
  write("usb", "bare_command", command(1, CommandFlags::kResync, 0).substr(1));
  write("usb", "bare_report", report(1, 0, 10).substr(1));
  std::string oversized(1, static_cast<char>(80));
  oversized += command(1, 0, 0).substr(1);
  oversized.resize(81, '\0');
  write("usb", "oversized", oversized + command(2, CommandFlags::kResync, 0));
}

// ---- usb, protocol version 2 (n channels): the same [u8 length][packet] stream ----

std::string command_v2(std::uint32_t seq, std::uint8_t flags, std::uint8_t n, std::int16_t dac) {
  usb::CommandPacketV2 c;
  c.sequence = seq;
  c.flags = flags;
  c.channels = n;
  for (std::size_t i = 0; i < n; ++i) {
    c.actuator_dac[i] = static_cast<std::int16_t>(i % 2 == 0 ? dac : -dac);
  }
  usb::PacketBuffer b{};
  std::size_t size = 0;
  if (usb::encode(c, b, size) != usb::PacketError::kNone) throw std::runtime_error("command v2");
  return packet(std::span<const std::uint8_t>(b.data(), size));
}

std::string report_v2(std::uint32_t seq, std::uint8_t flags, std::uint8_t n, std::int16_t adc) {
  usb::ReportPacketV2 r;
  r.sequence = seq;
  r.device_time_us = 1000ULL * seq;
  r.flags = flags;
  r.channels = n;
  r.last_command_sequence = seq > 0 ? seq - 1 : 0;
  for (std::size_t i = 0; i < n; ++i) {
    r.encoder_counts[i] = -1234 * static_cast<std::int32_t>(i + 1);
    r.load_cell_adc[i] = adc;
  }
  usb::PacketBuffer b{};
  std::size_t size = 0;
  if (usb::encode(r, b, size) != usb::PacketError::kNone) throw std::runtime_error("report v2");
  return packet(std::span<const std::uint8_t>(b.data(), size));
}

void usb_v2_seeds() {
  using usb::CommandFlags;
  // A v2 host session at n = 3 (the fuzz harness's v2 emulator has 3 channels): resync, enabled
  // commands, a duplicate, a command of another n (channel_mismatch), then disabled.
  std::string session = command_v2(200, CommandFlags::kResync, 3, 0);
  for (std::uint32_t s = 201; s < 206; ++s) {
    session += command_v2(s, CommandFlags::kEnable, 3, static_cast<std::int16_t>(5000 * (s - 200)));
  }
  session += command_v2(205, CommandFlags::kEnable, 3, 100);
  session += command_v2(206, CommandFlags::kEnable, 2, 100);
  session += command_v2(207, 0, 3, 0);
  write("usb", "v2_command_session", session);
  // A v1 host, then a v2 host, on the same device.
  write("usb", "v2_after_v1",
        command(1, CommandFlags::kResync, 0) + command(2, CommandFlags::kEnable, 700) +
            command_v2(3, CommandFlags::kEnable, 3, 700));
  // Reports at every n, 6 filling the 64-byte packet.
  std::string reports;
  for (std::uint8_t n = 1; n <= 6; ++n) {
    reports += report_v2(n, static_cast<std::uint8_t>(usb::ReportFlags::kLoadCellClipped), n,
                         static_cast<std::int16_t>(n * 1000));
  }
  write("usb", "v2_report_stream", reports);
  write("usb", "v2_bare_command", command_v2(1, CommandFlags::kResync, 6, 0).substr(1));
  write("usb", "v2_bare_report", report_v2(1, 0, 6, -32767).substr(1));
  // n = 7 (bad_channels, checked before the CRC), and an n = 3 command cut by one byte.
  std::string bad_n = command_v2(1, CommandFlags::kResync, 6, 0);
  bad_n[5] = 7;
  const std::string cut = command_v2(1, CommandFlags::kResync, 3, 0);
  std::string truncated(1, static_cast<char>(cut.size() - 2));
  truncated += cut.substr(1, cut.size() - 2);
  write("usb", "v2_bad_n_and_cut", bad_n + truncated);
}

// ---- dictionaries ----

void collect_names(const google::protobuf::Descriptor* d, std::set<std::string>& names,
                   std::set<const google::protobuf::Descriptor*>& seen) {
  if (!seen.insert(d).second) return;
  for (int i = 0; i < d->field_count(); ++i) {
    const google::protobuf::FieldDescriptor* f = d->field(i);
    names.insert(f->name());
    if (f->enum_type() != nullptr) {
      for (int j = 0; j < f->enum_type()->value_count(); ++j) {
        names.insert(f->enum_type()->value(j)->name());
      }
    }
    if (f->message_type() != nullptr) collect_names(f->message_type(), names, seen);
  }
}

void dictionaries() {
  fs::create_directories(g_root / "dict");
  std::set<std::string> names;
  std::set<const google::protobuf::Descriptor*> seen;
  collect_names(v1::SystemConfig::descriptor(), names, seen);
  std::ofstream config(g_root / "dict" / "config.dict", std::ios::trunc);
  config << "# Field and enum value names of teleop.v1.SystemConfig (fuzz_make_seeds).\n";
  for (const std::string& n : names) config << '"' << n << "\"\n";
  // Exponents: appended to a number they take it to the edges of double and of the int64
  // nanoseconds the loaders convert times to.
  for (const char* s : {": ", " { ", " }\\x0a", "[", "]", "nan", "inf", "-1e308", "1e-320", "e300",
                        "e-300", "e9", "e-9", "\\x0a#--set\\x0a", "={}", "true", "0x7fffffff"}) {
    config << '"' << s << "\"\n";
  }
  // NodeState: field tags (the axis fields of issue 18 among them), axis counts, packed lengths,
  // the doubles that must never pass, the CRC tag.
  std::ofstream node_state(g_root / "dict" / "node_state.dict", std::ios::trunc);
  node_state << "# NodeState tags and values (fuzz_make_seeds).\n";
  for (const char* s : {"\\x09",
                        "\\x10",
                        "\\x30\\x01",
                        "\\x30\\x02",
                        "\\x41",
                        "\\x49",
                        "\\x51",
                        "\\x5a",
                        "\\x81\\x01",
                        "\\x88\\x01",
                        "\\x7d",
                        "\\x90\\x01",
                        "\\x90\\x01\\x01",
                        "\\x90\\x01\\x03",
                        "\\x90\\x01\\x06",
                        "\\x90\\x01\\x07",
                        "\\x90\\x01\\xff\\xff\\xff\\xff\\x0f",
                        "\\x9a\\x01\\x18",
                        "\\xa2\\x01\\x18",
                        "\\xaa\\x01\\x18",
                        "\\x9a\\x01\\x30",
                        "\\x99\\x01",
                        "\\xa1\\x01",
                        "\\xa9\\x01",
                        "\\x00\\x00\\x00\\x00\\x00\\x00\\xf8\\x7f",
                        "\\x00\\x00\\x00\\x00\\x00\\x00\\xf0\\x7f",
                        "\\x00\\x00\\x00\\x00\\x00\\x00\\xf0\\xff",
                        "\\x00\\x00\\x00\\x00\\x00\\x00\\x00\\x80"}) {
    node_state << '"' << s << "\"\n";
  }
  std::ofstream mcap(g_root / "dict" / "mcap.dict", std::ios::trunc);
  mcap << "# MCAP magic, record prefixes and encodings.\n"
       << "\"\\x89MCAP0\\x0d\\x0a\"\n"
       << "\"protobuf\"\n\"teleop\"\n"
       << "\"\\x0f\\x04\\x00\\x00\\x00\\x00\\x00\\x00\\x00\"\n"  // Data End, 4 bytes
       << "\"\\x02\\x14\\x00\\x00\\x00\\x00\\x00\\x00\\x00\"\n"  // Footer, 20 bytes
       << "\"\\x06\"\n\"\\x05\"\n\"\\x08\"\n\"\\x07\"\n\"\\x0b\"\n";
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: fuzz_make_seeds FUZZ_DIR\n";
    return 2;
  }
  try {
    g_root = argv[1];
    node_state_seeds();
    node_state_axes_seeds();
    command_seeds();
    config_seeds();
    mcap_seeds();
    usb_seeds();
    usb_v2_seeds();
    dictionaries();
  } catch (const std::exception& e) {
    std::cerr << "fuzz_make_seeds: " << e.what() << "\n";
    return 1;
  }
  std::cout << "seeds written under " << g_root.string() << "\n";
  return 0;
}
