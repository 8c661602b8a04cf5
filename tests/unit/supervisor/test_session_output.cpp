// What SupervisorCore writes into a session beyond its published messages (issue 17): one
// message per cycle on /<node>/cycle with the node's sample time as publish_time and log times
// on the wall clock, alarms as foxglove.Log with the documented severity mapping, the metadata
// and the configuration attachment. Expected values come from the telemetry the test sends,
// the documented conventions (common/record/session.hpp) and CMake's project version.
#include <gtest/gtest.h>

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/config/control_fingerprint.hpp"
#include "common/record/session.hpp"
#include "foxglove/Log.pb.h"
#include "supervisor/core/session_output.hpp"
#include "supervisor/core/supervisor_core.hpp"

namespace teleop::supervisor {
namespace {

constexpr std::int64_t kMs = 1'000'000;
// 2023-11-14T22:13:20Z: an arbitrary wall clock, far from any monotonic clock.
constexpr std::int64_t kWallOffsetNs = 1'700'000'000'000'000'000;

const std::string kConfigText =
    "# the paddles, as a user wrote them\n"
    "sample_rate_hz: 1000\n"
    "round_trip_delay_samples: 1\n"
    "master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 } }\n"
    "slave { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 }\n"
    "        fixture { stiffness_N_per_m: 1000 position_m: 0.006 } }\n"
    "gains { kpm: 600 kps: 600 kdm: 2 kds: 2 }\n"
    "human { fixed { mass_kg: 0.012 damping_Ns_per_m: 0.76 stiffness_N_per_m: 70 } }\n";

struct Captured {
  std::string topic;
  std::string type;
  std::int64_t log_time_ns;
  std::int64_t publish_time_ns;
  std::string bytes;
};

class CapturingSink final : public record::SessionSink {
 public:
  void record(std::string_view topic, const std::string& type, std::int64_t log_time_ns,
              const std::string& bytes) override {
    messages.push_back({std::string(topic), type, log_time_ns, log_time_ns, bytes});
  }
  void record_published(std::string_view topic, const std::string& type, std::int64_t log_time_ns,
                        std::int64_t publish_time_ns, const std::string& bytes) override {
    messages.push_back({std::string(topic), type, log_time_ns, publish_time_ns, bytes});
  }
  void metadata(std::string_view name, const std::map<std::string, std::string>& values) override {
    metadata_records[std::string(name)] = values;
  }
  void attachment(std::string_view name, std::string_view media_type, std::int64_t log_time_ns,
                  const std::string& data) override {
    attachments.push_back({std::string(name), std::string(media_type), log_time_ns, 0, data});
  }
  [[nodiscard]] std::vector<Captured> on(std::string_view topic) const {
    std::vector<Captured> out;
    for (const Captured& c : messages) {
      if (c.topic == topic) out.push_back(c);
    }
    return out;
  }

  std::vector<Captured> messages;
  std::map<std::string, std::map<std::string, std::string>> metadata_records;
  std::vector<Captured> attachments;  // topic = name, type = media type
};

class SilentPorts final : public SupervisorPorts {
 public:
  std::optional<v1::NodeCommandReply> command(Side, const v1::NodeCommand&) override {
    return std::nullopt;
  }
  void report(const v1::StabilityReport&) override {}
  void alarm(const v1::Alarm&) override {}
  void status(const v1::SupervisorStatus&) override {}
};

// A slave telemetry message of `count` cycles at 1 ms, the last at `newest_sample_ns`.
v1::Telemetry slave_telemetry(std::uint64_t session, std::int64_t newest_sample_ns, int count) {
  v1::Telemetry t;
  t.set_session_id(session);
  t.set_role(v1::SLAVE);
  t.set_mode(v1::ARMED);
  t.mutable_rt()->set_fifo_priority(80);
  t.mutable_rt()->set_memory_locked(true);
  t.mutable_rt()->set_cpu(3);
  t.mutable_rt()->add_refused("cpu_dma_latency: permission denied");
  for (int i = 0; i < count; ++i) {
    v1::CycleRecord* c = t.add_cycles();
    c->set_sequence(static_cast<std::uint64_t>(100 + i));
    c->set_sample_time_ns(newest_sample_ns - (count - 1 - i) * kMs);
    c->set_mode(v1::ARMED);
    c->set_position_m(0.001 * i);
    c->set_force_n(0.5 * i);
  }
  return t;
}

struct Session {
  CapturingSink* sink{nullptr};
  SilentPorts ports;
  std::optional<SupervisorCore> core;
};

void start(Session& s) {
  const config::LoadedConfig loaded = config::load_config_text(kConfigText, "paddles.textproto");
  SupervisorOptions o;
  auto sink = std::make_unique<CapturingSink>();
  s.sink = sink.get();
  o.sink = std::move(sink);
  o.log_time_offset_ns = kWallOffsetNs;
  o.config_text = kConfigText;
  s.core.emplace(loaded, std::move(o), s.ports);
  s.core->start(1000 * kMs);
}

TEST(SessionOutput, EveryCycleOnItsOwnChannelWithSampleTimeAndWallClockLogTime) {
  Session s;
  start(s);
  // The batch arrives at 1050 ms on the core's clock; its cycles were sampled at 21..40 ms on
  // the node's own monotonic clock.
  const v1::Telemetry t = slave_telemetry(22, 40 * kMs, 20);
  s.core->on_telemetry(Side::kSlave, t, 1050 * kMs);
  const std::vector<Captured> cycles = s.sink->on(record::topic::kSlaveCycle);
  ASSERT_EQ(cycles.size(), 20U);
  EXPECT_TRUE(s.sink->on(record::topic::kMasterCycle).empty());
  for (std::size_t i = 0; i < cycles.size(); ++i) {
    EXPECT_EQ(cycles[i].type, "teleop.v1.CycleRecord");
    v1::CycleRecord c;
    ASSERT_TRUE(c.ParseFromString(cycles[i].bytes));
    EXPECT_EQ(c.session_id(), 22U);
    EXPECT_EQ(c.sequence(), 100 + i);
    EXPECT_EQ(c.position_m(), 0.001 * static_cast<double>(i));
    // publish_time: the node's sample time; log_time: receipt on the wall clock, earlier
    // cycles 1 ms apart before it.
    EXPECT_EQ(cycles[i].publish_time_ns, (21 + static_cast<std::int64_t>(i)) * kMs);
    EXPECT_EQ(cycles[i].log_time_ns,
              kWallOffsetNs + 1050 * kMs - (19 - static_cast<std::int64_t>(i)) * kMs);
  }
  // The batch itself keeps its channel, logged at receipt.
  const std::vector<Captured> batch = s.sink->on(record::topic::kSlaveTelemetry);
  ASSERT_EQ(batch.size(), 1U);
  EXPECT_EQ(batch[0].log_time_ns, kWallOffsetNs + 1050 * kMs);
  // Every message's log time is on the wall clock (the configuration at start, 1000 ms).
  const std::vector<Captured> config = s.sink->on(record::topic::kConfig);
  ASSERT_EQ(config.size(), 1U);
  EXPECT_EQ(config[0].log_time_ns, kWallOffsetNs + 1000 * kMs);
}

TEST(SessionOutput, MetadataAndTheConfigurationAttachmentAtStart) {
  Session s;
  start(s);
  const auto& md = s.sink->metadata_records;
  ASSERT_TRUE(md.count("teleop"));
  EXPECT_EQ(md.at("teleop").at("version"), TELEOP_PROJECT_VERSION);
  EXPECT_FALSE(md.at("teleop").at("host").empty());
  EXPECT_EQ(md.at("teleop").at("config_file"), "paddles.textproto");
  // The fingerprint every node computes of the same file.
  EXPECT_EQ(md.at("teleop").at("config_fingerprint"),
            config::fingerprint_hex(config::control_fingerprint(
                config::load_config_text(kConfigText, "paddles.textproto"))));
  EXPECT_EQ(md.at("teleop").at("started_utc"), "2023-11-14T22:13:21.000Z");  // + 1000 ms
  ASSERT_TRUE(md.count("teleop.analysis"));
  EXPECT_EQ(md.at("teleop.analysis").at("verdict"), "stable");
  EXPECT_EQ(md.at("teleop.analysis").at("round_trip_samples"), "1");
  EXPECT_EQ(md.at("teleop.analysis").at("slave_fixture_stiffness_N_per_m"), "1000");
  ASSERT_EQ(s.sink->attachments.size(), 1U);
  EXPECT_EQ(s.sink->attachments[0].topic, "config.textproto");
  EXPECT_EQ(s.sink->attachments[0].type, "text/plain");
  EXPECT_EQ(s.sink->attachments[0].bytes, kConfigText);  // as read, comment and all
  EXPECT_EQ(s.sink->attachments[0].log_time_ns, kWallOffsetNs + 1000 * kMs);
  // A node's RT settings once its first telemetry arrived, not before.
  EXPECT_FALSE(md.count("teleop.rt.slave"));
  s.core->on_telemetry(Side::kSlave, slave_telemetry(22, 40 * kMs, 20), 1050 * kMs);
  ASSERT_TRUE(md.count("teleop.rt.slave"));
  EXPECT_EQ(md.at("teleop.rt.slave").at("fifo_priority"), "80");
  EXPECT_EQ(md.at("teleop.rt.slave").at("memory_locked"), "true");
  EXPECT_EQ(md.at("teleop.rt.slave").at("cpu"), "3");
  EXPECT_EQ(md.at("teleop.rt.slave").at("refused"), "cpu_dma_latency: permission denied");
  EXPECT_FALSE(md.count("teleop.rt.master"));
}

TEST(SessionOutput, AnAlarmIsAlsoAFoxgloveLogAtTheSameLogTime) {
  Session s;
  start(s);
  s.core->on_telemetry(Side::kSlave, slave_telemetry(22, 40 * kMs, 20), 1050 * kMs);
  // A restarted slave (new session id): a WARNING node_state alarm.
  s.core->on_telemetry(Side::kSlave, slave_telemetry(23, 10 * kMs, 5), 1070 * kMs);
  const std::vector<Captured> alarms = s.sink->on(record::topic::kAlarms);
  const std::vector<Captured> logs = s.sink->on(record::topic::kLog);
  ASSERT_EQ(logs.size(), alarms.size());
  ASSERT_FALSE(logs.empty());
  const Captured& last = logs.back();
  EXPECT_EQ(last.type, "foxglove.Log");
  EXPECT_EQ(last.log_time_ns, kWallOffsetNs + 1070 * kMs);
  foxglove::Log log;
  ASSERT_TRUE(log.ParseFromString(last.bytes));
  EXPECT_EQ(log.level(), foxglove::Log::WARNING);
  EXPECT_EQ(log.timestamp().seconds(), 1'700'000'001);
  EXPECT_EQ(log.timestamp().nanos(), 70'000'000);
  EXPECT_EQ(log.name(), "teleop-supervisor/slave");
  EXPECT_NE(log.message().find("node_state: restarted (new session)"), std::string::npos)
      << log.message();
}

TEST(SessionOutput, AlarmSeverityMapsToFoxgloveLevelsAsDocumented) {
  // common/record/session.hpp: INFO -> INFO, WARNING and ACTION -> WARNING, CRITICAL -> ERROR.
  const std::vector<std::pair<v1::Alarm::Severity, foxglove::Log::Level>> expected = {
      {v1::Alarm::SEVERITY_UNSPECIFIED, foxglove::Log::UNKNOWN},
      {v1::Alarm::INFO, foxglove::Log::INFO},
      {v1::Alarm::WARNING, foxglove::Log::WARNING},
      {v1::Alarm::ACTION, foxglove::Log::WARNING},
      {v1::Alarm::CRITICAL, foxglove::Log::ERROR}};
  for (const auto& [severity, level] : expected) {
    v1::Alarm a;
    a.set_severity(severity);
    a.set_kind("oscillation");
    a.set_side("");
    a.set_message("slave oscillates");
    a.set_action("lowered fixtures");
    const foxglove::Log log = to_foxglove_log(a, 5 * 1'000'000'000LL + 7);
    EXPECT_EQ(log.level(), level) << v1::Alarm::Severity_Name(severity);
    EXPECT_EQ(log.timestamp().seconds(), 5);
    EXPECT_EQ(log.timestamp().nanos(), 7);
    EXPECT_EQ(log.name(), "teleop-supervisor/system");
    EXPECT_EQ(log.message(), "oscillation: slave oscillates (action: lowered fixtures)");
  }
}

}  // namespace
}  // namespace teleop::supervisor
