// Writes sample session files with the project's real protos (teleop.v1.NodeState,
// teleop.v1.Telemetry) for the independent reader check (tests/mcap_js/verify.mjs), each with
// NAME.expected.json = {"messages":N,"topics":{...}} known from what was written:
//   session.mcap    complete, indexed
//   cut.mcap        cut 100 bytes into a chunk after a flush boundary (no summary, no footer)
//   recovered.mcap  recover_file(cut.mcap)
// usage: mcap_js_sample OUTPUT_DIR
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <vector>

#include "common/record/mcap_reader.hpp"
#include "common/record/mcap_writer.hpp"
#include "common/record/proto_schema.hpp"
#include "teleop/v1/node_state.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace {

using teleop::record::McapWriter;

const std::vector<std::string> kTopics{"/master/state", "/slave/state", "/master/telemetry",
                                       "/slave/telemetry"};

std::string expected_json(const std::vector<int>& topic_of, std::uint64_t count) {
  std::map<std::string, std::uint64_t> per_topic;
  for (std::uint64_t i = 0; i < count; ++i)
    ++per_topic[kTopics[static_cast<std::size_t>(topic_of[i])]];
  std::string out = "{\"messages\":" + std::to_string(count) + ",\"topics\":{";
  bool first = true;
  for (const auto& [topic, n] : per_topic) {
    out += (first ? "\"" : ",\"") + topic + "\":" + std::to_string(n);
    first = false;
  }
  return out + "}}\n";
}

void write_text(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
  if (!out) throw std::runtime_error("cannot write " + path.string());
}

teleop::v1::NodeState node_state(teleop::v1::NodeRole role, std::uint64_t k) {
  teleop::v1::NodeState s;
  s.set_session_id(role == teleop::v1::MASTER ? 0x1234567890ABCDEFULL : 0xFEDCBA0987654321ULL);
  s.set_sequence(k);
  s.set_sample_time_ns(static_cast<std::int64_t>(k) * 1'000'000 + 17);
  s.set_last_peer_sequence(k > 2 ? k - 2 : 0);
  s.set_peer_age_ns(430'000);
  s.set_role(role);
  s.set_mode(k < 300 ? teleop::v1::ALIGNING : teleop::v1::ENGAGED);
  const double t = static_cast<double>(k) * 1e-3;
  s.set_position_m(0.01 * std::sin(2.0 * M_PI * 0.5 * t));
  s.set_velocity_m_per_s(0.01 * M_PI * std::cos(2.0 * M_PI * 0.5 * t));
  s.set_force_n(role == teleop::v1::SLAVE ? 1.5 * std::sin(t) : 0.0);
  s.mutable_fixture()->set_in_contact(k % 500 > 400);
  s.mutable_fixture()->set_penetration_m(k % 500 > 400 ? 1e-4 : 0.0);
  s.set_clutched(false);
  s.set_fault_flags(0);
  s.set_crc32(static_cast<std::uint32_t>(k * 2654435761u));
  return s;
}

teleop::v1::Telemetry telemetry(teleop::v1::NodeRole role, std::uint64_t k) {
  teleop::v1::Telemetry t;
  t.set_session_id(0x1234567890ABCDEFULL);
  t.set_role(role);
  t.set_mode(teleop::v1::ENGAGED);
  t.set_mode_reason("engaged by operator");
  t.set_sent_time_ns(static_cast<std::int64_t>(k) * 1'000'000);
  t.mutable_loop()->set_period_s(1e-3);
  t.mutable_loop()->set_cycles(k);
  t.mutable_loop()->set_wakeup_p99_ns(21'000);
  t.mutable_link()->set_accepted(k);
  t.mutable_link()->set_round_trip_ns(850'000);
  t.mutable_link()->set_loss_fraction(0.001);
  t.mutable_rt()->set_fifo_priority(80);
  t.mutable_rt()->add_refused("mlockall: Operation not permitted");
  for (std::uint64_t c = k - 99; c <= k; ++c) {
    teleop::v1::CycleRecord* r = t.add_cycles();
    r->set_sequence(c);
    r->set_sample_time_ns(static_cast<std::int64_t>(c) * 1'000'000);
    r->set_mode(teleop::v1::ENGAGED);
    r->set_position_m(1e-3 * static_cast<double>(c % 17));
    r->set_command_n(-0.25 * static_cast<double>(c % 5));
    r->set_coupling_weight(1.0);
    r->set_flags(static_cast<std::uint32_t>(c % 3) << 8);
    r->set_wakeup_latency_ns(static_cast<std::int64_t>(5'000 + c % 900));
  }
  return t;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s OUTPUT_DIR\n", argv[0]);
    return 2;
  }
  try {
    const std::filesystem::path dir = argv[1];
    std::filesystem::create_directories(dir);
    teleop::record::WriterOptions options{};
    options.chunk_size_bytes = 16 * 1024;
    // A clock that never moves: chunks by size only, so the sample is the same every run.
    options.clock = [] { return std::chrono::steady_clock::time_point{}; };
    std::vector<int> topic_of;  // per message written, in order
    struct Boundary {
      std::uint64_t file_size;
      std::uint64_t messages;
    };
    std::vector<Boundary> boundaries;
    {
      McapWriter w(dir / "session.mcap", options);
      const auto state =
          w.add_schema(teleop::record::protobuf_schema(teleop::v1::NodeState::descriptor()));
      const auto tel =
          w.add_schema(teleop::record::protobuf_schema(teleop::v1::Telemetry::descriptor()));
      const std::uint16_t channel[4] = {
          w.add_channel(teleop::record::protobuf_channel(state, kTopics[0], {{"node", "master"}})),
          w.add_channel(teleop::record::protobuf_channel(state, kTopics[1], {{"node", "slave"}})),
          w.add_channel(teleop::record::protobuf_channel(tel, kTopics[2], {{"node", "master"}})),
          w.add_channel(teleop::record::protobuf_channel(tel, kTopics[3], {{"node", "slave"}}))};
      const auto put = [&](int topic, std::uint64_t time, const std::string& bytes) {
        const std::uint64_t chunks = w.chunks_written();
        if (!w.write(channel[topic], time, bytes)) throw std::runtime_error(w.error());
        topic_of.push_back(topic);
        if (w.chunks_written() != chunks)
          boundaries.push_back({w.file_size(), w.messages_written()});
      };
      const std::uint64_t t0 = 1'700'000'000'000'000'000ULL;
      for (std::uint64_t k = 0; k < 2000; ++k) {
        const std::uint64_t now = t0 + k * 1'000'000;
        put(0, now, node_state(teleop::v1::MASTER, k).SerializeAsString());
        put(1, now + 3'000, node_state(teleop::v1::SLAVE, k).SerializeAsString());
        if (k % 100 == 99) {
          put(2, now + 50'000, telemetry(teleop::v1::MASTER, k).SerializeAsString());
          put(3, now + 60'000, telemetry(teleop::v1::SLAVE, k).SerializeAsString());
        }
      }
      if (!w.close()) throw std::runtime_error(w.error());
    }
    write_text(dir / "session.expected.json", expected_json(topic_of, topic_of.size()));

    if (boundaries.size() < 4) throw std::runtime_error("the sample has too few chunks");
    const Boundary cut = boundaries[boundaries.size() / 2];
    std::ifstream in(dir / "session.mcap", std::ios::binary);
    const std::string whole{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
    std::ofstream out(dir / "cut.mcap", std::ios::binary | std::ios::trunc);
    out.write(whole.data(), static_cast<std::streamsize>(cut.file_size + 100));
    out.close();
    write_text(dir / "cut.expected.json", expected_json(topic_of, cut.messages));

    const auto report = teleop::record::recover_file(dir / "cut.mcap", dir / "recovered.mcap");
    if (report.messages != cut.messages) {
      throw std::runtime_error("recover_file kept " + std::to_string(report.messages) +
                               " messages, expected " + std::to_string(cut.messages));
    }
    write_text(dir / "recovered.expected.json", expected_json(topic_of, cut.messages));
    std::printf("mcap_js_sample: %zu messages, %zu chunks; cut at byte %llu keeps %llu\n",
                topic_of.size(), boundaries.size(),
                static_cast<unsigned long long>(cut.file_size + 100),
                static_cast<unsigned long long>(cut.messages));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcap_js_sample: %s\n", e.what());
    return 1;
  }
  return 0;
}
