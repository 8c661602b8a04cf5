// The session library (common/session/session_reader.hpp, session_stats.hpp) on files written by
// the live session recorder (make_session_recorder_at): every typed value read back is checked
// against the value the test wrote, never against the reader's own output.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/record/session.hpp"
#include "common/record/session_recorder.hpp"
#include "common/session/session_reader.hpp"
#include "common/session/session_stats.hpp"
#include "tests/unit/record/record_test_util.hpp"

namespace teleop::record {
namespace {

namespace fs = std::filesystem;
using test::TempDir;

// The values one cycle is written with: every field distinct, derived from `k`.
v1::CycleRecord cycle_proto(std::uint64_t sequence, std::int64_t sample_time_ns, v1::NodeMode mode,
                            double k) {
  v1::CycleRecord c;
  c.set_sequence(sequence);
  c.set_sample_time_ns(sample_time_ns);
  c.set_mode(mode);
  c.set_position_m(0.001 * k);
  c.set_velocity_m_per_s(0.01 * k + 0.5);
  c.set_force_n(-0.25 * k);
  c.set_command_n(0.125 * k - 1.0);
  c.set_peer_sequence(sequence + 100);
  c.set_peer_position_m(-0.002 * k);
  c.set_peer_age_ns(1000 + static_cast<std::int64_t>(k));
  c.set_coupling_weight(0.5);
  c.set_flags(0x100U | static_cast<std::uint32_t>(k));
  c.set_wakeup_latency_ns(20'000 + static_cast<std::int64_t>(k));
  c.set_round_trip_ns(3'000'000 + static_cast<std::int64_t>(k));
  c.set_master_sequence(sequence + 7);
  c.set_parameter_change_id(static_cast<std::uint64_t>(k) % 3);
  c.set_alignment_error_m(1e-4 * k);
  return c;
}

void record(SessionSink& sink, std::string_view topic, std::int64_t log_time_ns,
            const google::protobuf::Message& m) {
  sink.record(topic, m.GetDescriptor()->full_name(), log_time_ns, m.SerializeAsString());
}

// A session with every topic, written in the order a supervisor would (log times interleaved).
struct WrittenSession {
  v1::SystemConfig config{};
  std::vector<v1::Telemetry> master{};  // log times 2000, 4000
  std::vector<v1::Telemetry> slave{};   // log time 3000
  v1::StabilityReport report{};         // log time 2500
  std::vector<v1::Alarm> alarms{};      // log times 3500, 4500
  v1::ParameterChangeRecord change{};   // log time 5000
  v1::SupervisorStatus status{};        // log time 6000
};

WrittenSession write_session(const fs::path& file) {
  WrittenSession w;
  w.config.set_sample_rate_hz(1000.0);
  w.config.mutable_gains()->set_kpm(600.0);
  w.config.mutable_gains()->set_kps(700.0);

  v1::Telemetry m1;
  m1.set_session_id(0xAAAA);
  *m1.add_cycles() = cycle_proto(1, 1'000'000, v1::ENGAGED, 1.0);
  *m1.add_cycles() = cycle_proto(2, 2'000'000, v1::CLUTCHED, 2.0);
  // A flight record repeats cycles: never read as cycles.
  *m1.add_flight_record() = cycle_proto(1, 1'000'000, v1::ENGAGED, 1.0);
  v1::Telemetry m2;
  m2.set_session_id(0xBBBB);
  *m2.add_cycles() = cycle_proto(1, 5'000'000, v1::FAULT, 3.0);
  w.master = {m1, m2};

  v1::Telemetry s1;
  s1.set_session_id(0xCCCC);
  *s1.add_cycles() = cycle_proto(10, 1'500'000, v1::ALIGNING, 4.0);
  *s1.add_cycles() = cycle_proto(11, 2'500'000, v1::SAFE, 5.0);
  w.slave = {s1};

  w.report.set_time_ns(42);
  w.report.set_verdict("stable");
  w.report.set_min_damping_ratio(0.125);
  w.report.set_slave_fixture_stiffness_n_per_m(800.0);

  v1::Alarm a1;
  a1.set_kind("oscillation");
  a1.set_side("slave");
  a1.set_severity(v1::Alarm::WARNING);
  v1::Alarm a2;
  a2.set_kind("heartbeat");
  a2.set_side("master");
  a2.set_severity(v1::Alarm::CRITICAL);
  a2.set_action("disengaged");
  w.alarms = {a1, a2};

  w.change.mutable_request()->set_slave_fixture_stiffness_n_per_m(900.0);
  w.change.mutable_request()->set_requested_by("console");
  w.change.mutable_reply()->set_accepted(true);
  w.change.mutable_reply()->set_change_id(3);

  w.status.set_recording_drops(17);
  w.status.set_recorded_messages(9);

  const std::unique_ptr<SessionSink> sink = make_session_recorder_at(file);
  record(*sink, topic::kConfig, 1000, w.config);
  record(*sink, topic::kMasterTelemetry, 2000, m1);
  record(*sink, topic::kStability, 2500, w.report);
  record(*sink, topic::kSlaveTelemetry, 3000, s1);
  record(*sink, topic::kAlarms, 3500, a1);
  record(*sink, topic::kMasterTelemetry, 4000, m2);
  record(*sink, topic::kAlarms, 4500, a2);
  record(*sink, topic::kParameterChanges, 5000, w.change);
  record(*sink, topic::kStatus, 6000, w.status);
  return w;  // the sink closes the file as it goes out of scope
}

void expect_cycle(const RecordedCycle& r, std::uint64_t session_id, std::uint64_t sequence,
                  std::int64_t sample_time_ns, node::Mode mode, double k) {
  SCOPED_TRACE("cycle " + std::to_string(sequence));
  EXPECT_EQ(r.session_id, session_id);
  const node::CycleRecord& c = r.cycle;
  EXPECT_EQ(c.sequence, sequence);
  EXPECT_EQ(c.sample_time_ns, sample_time_ns);
  EXPECT_EQ(c.mode, mode);
  EXPECT_STREQ(c.reason, "");
  EXPECT_EQ(c.position_m, 0.001 * k);
  EXPECT_EQ(c.velocity_m_per_s, 0.01 * k + 0.5);
  EXPECT_EQ(c.force_N, -0.25 * k);
  EXPECT_EQ(c.command_N, 0.125 * k - 1.0);
  EXPECT_EQ(c.peer_sequence, sequence + 100);
  EXPECT_EQ(c.peer_position_m, -0.002 * k);
  EXPECT_EQ(c.peer_age_ns, 1000 + static_cast<std::int64_t>(k));
  EXPECT_EQ(c.coupling_weight, 0.5);
  EXPECT_EQ(c.flags, 0x100U | static_cast<std::uint32_t>(k));
  EXPECT_EQ(c.wakeup_latency_ns, 20'000 + static_cast<std::int64_t>(k));
  EXPECT_EQ(c.round_trip_ns, 3'000'000 + static_cast<std::int64_t>(k));
  EXPECT_EQ(c.master_sequence, sequence + 7);
  EXPECT_EQ(c.parameter_change_id, static_cast<std::uint64_t>(k) % 3);
  EXPECT_EQ(c.alignment_error_m, 1e-4 * k);
}

TEST(SessionReader, CyclesOfEachNodeAsWritten) {
  const TempDir dir;
  (void)write_session(dir / "s.mcap");
  const SessionReader session = SessionReader::open(dir / "s.mcap");

  const std::vector<RecordedCycle> master = session.cycles(true);
  ASSERT_EQ(master.size(), 3U);  // the flight record left out
  expect_cycle(master[0], 0xAAAA, 1, 1'000'000, node::Mode::kEngaged, 1.0);
  expect_cycle(master[1], 0xAAAA, 2, 2'000'000, node::Mode::kClutched, 2.0);
  expect_cycle(master[2], 0xBBBB, 1, 5'000'000, node::Mode::kFault, 3.0);

  const std::vector<RecordedCycle> slave = session.cycles(false);
  ASSERT_EQ(slave.size(), 2U);
  expect_cycle(slave[0], 0xCCCC, 10, 1'500'000, node::Mode::kAligning, 4.0);
  expect_cycle(slave[1], 0xCCCC, 11, 2'500'000, node::Mode::kSafe, 5.0);
}

TEST(SessionReader, APassReportsHowFarItIsThroughTheFile) {
  const TempDir dir;
  (void)write_session(dir / "s.mcap");
  const SessionReader session = SessionReader::open(dir / "s.mcap");
  const std::uint64_t size = fs::file_size(dir / "s.mcap");
  for (const bool master : {true, false}) {
    std::vector<std::pair<std::uint64_t, std::uint64_t>> read;
    const std::vector<RecordedCycle> cycles = session.cycles(
        master, [&](std::uint64_t done, std::uint64_t total) { read.emplace_back(done, total); });
    // The same cycles as without (CyclesOfEachNodeAsWritten checks them against the writer's).
    EXPECT_EQ(cycles.size(), session.cycles(master).size());
    ASSERT_FALSE(read.empty());
    for (std::size_t i = 0; i < read.size(); ++i) {
      EXPECT_EQ(read[i].second, size) << i;
      if (i > 0) {
        EXPECT_GE(read[i].first, read[i - 1].first) << i;
      }
    }
    // Ends at the file's size; before that, inside the data (past the magic and the Header).
    EXPECT_EQ(read.back().first, size);
    for (std::size_t i = 0; i + 1 < read.size(); ++i) {
      EXPECT_GT(read[i].first, 8U);
      EXPECT_LT(read[i].first, size);
    }
  }
  std::uint64_t config_done = 0;
  ASSERT_TRUE(session.config([&](std::uint64_t done, std::uint64_t) { config_done = done; }));
  EXPECT_EQ(config_done, size);
}

TEST(SessionReader, ConfigurationReportsAlarmsChangesAndStatusAsWritten) {
  const TempDir dir;
  (void)write_session(dir / "s.mcap");
  const SessionReader session = SessionReader::open(dir / "s.mcap");

  const std::optional<v1::SystemConfig> config = session.config();
  ASSERT_TRUE(config.has_value());
  EXPECT_EQ(config->sample_rate_hz(), 1000.0);
  EXPECT_EQ(config->gains().kpm(), 600.0);
  EXPECT_EQ(config->gains().kps(), 700.0);

  const auto reports = session.reports();
  ASSERT_EQ(reports.size(), 1U);
  EXPECT_EQ(reports[0].log_time_ns, 2500U);
  EXPECT_EQ(reports[0].message.time_ns(), 42);
  EXPECT_EQ(reports[0].message.verdict(), "stable");
  EXPECT_EQ(reports[0].message.min_damping_ratio(), 0.125);
  EXPECT_EQ(reports[0].message.slave_fixture_stiffness_n_per_m(), 800.0);

  const auto alarms = session.alarms();
  ASSERT_EQ(alarms.size(), 2U);
  EXPECT_EQ(alarms[0].log_time_ns, 3500U);
  EXPECT_EQ(alarms[0].message.kind(), "oscillation");
  EXPECT_EQ(alarms[0].message.side(), "slave");
  EXPECT_EQ(alarms[0].message.severity(), v1::Alarm::WARNING);
  EXPECT_EQ(alarms[1].log_time_ns, 4500U);
  EXPECT_EQ(alarms[1].message.kind(), "heartbeat");
  EXPECT_EQ(alarms[1].message.severity(), v1::Alarm::CRITICAL);
  EXPECT_EQ(alarms[1].message.action(), "disengaged");

  const auto changes = session.parameter_changes();
  ASSERT_EQ(changes.size(), 1U);
  EXPECT_EQ(changes[0].log_time_ns, 5000U);
  EXPECT_EQ(changes[0].message.request().slave_fixture_stiffness_n_per_m(), 900.0);
  EXPECT_EQ(changes[0].message.request().requested_by(), "console");
  EXPECT_TRUE(changes[0].message.reply().accepted());
  EXPECT_EQ(changes[0].message.reply().change_id(), 3U);

  const auto statuses = session.statuses();
  ASSERT_EQ(statuses.size(), 1U);
  EXPECT_EQ(statuses[0].log_time_ns, 6000U);
  EXPECT_EQ(statuses[0].message.recording_drops(), 17U);
  EXPECT_EQ(statuses[0].message.recorded_messages(), 9U);

  EXPECT_EQ(session.first_log_time_ns(), 1000U);
  EXPECT_EQ(session.last_log_time_ns(), 6000U);
  for (const std::string_view t :
       {topic::kConfig, topic::kMasterTelemetry, topic::kSlaveTelemetry, topic::kStability,
        topic::kAlarms, topic::kParameterChanges, topic::kStatus}) {
    EXPECT_TRUE(session.has_topic(t)) << t;
    EXPECT_NE(session.channel_list().find(std::string(t)), std::string::npos) << t;
  }
  EXPECT_FALSE(session.has_topic("/nope"));
}

TEST(SessionReader, VisitHandsOutEveryMessageTypedInLogTimeOrder) {
  const TempDir dir;
  (void)write_session(dir / "s.mcap");
  const SessionReader session = SessionReader::open(dir / "s.mcap");
  std::vector<std::uint64_t> every;
  std::vector<std::string> typed;
  SessionVisitor v;
  v.message = [&](const MessageView& m) { every.push_back(m.log_time_ns); };
  v.telemetry = [&](std::uint64_t t, bool master, const v1::Telemetry& m) {
    typed.push_back(std::to_string(t) + (master ? " master " : " slave ") +
                    std::to_string(m.session_id()));
  };
  v.report = [&](std::uint64_t t, const v1::StabilityReport& r) {
    typed.push_back(std::to_string(t) + " report " + r.verdict());
  };
  v.alarm = [&](std::uint64_t t, const v1::Alarm& a) {
    typed.push_back(std::to_string(t) + " alarm " + a.kind());
  };
  v.parameter_change = [&](std::uint64_t t, const v1::ParameterChangeRecord& r) {
    typed.push_back(std::to_string(t) + " change " + std::to_string(r.reply().change_id()));
  };
  v.status = [&](std::uint64_t t, const v1::SupervisorStatus& s) {
    typed.push_back(std::to_string(t) + " status " + std::to_string(s.recording_drops()));
  };
  session.visit(v);
  EXPECT_EQ(every,
            (std::vector<std::uint64_t>{1000, 2000, 2500, 3000, 3500, 4000, 4500, 5000, 6000}));
  EXPECT_EQ(typed, (std::vector<std::string>{
                       "2000 master " + std::to_string(0xAAAA), "2500 report stable",
                       "3000 slave " + std::to_string(0xCCCC), "3500 alarm oscillation",
                       "4000 master " + std::to_string(0xBBBB), "4500 alarm heartbeat",
                       "5000 change 3", "6000 status 17"}));
}

TEST(SessionReader, RecorderDropsFromTheSupervisorsStatus) {
  const TempDir dir;
  (void)write_session(dir / "s.mcap");
  const SessionReader session = SessionReader::open(dir / "s.mcap");
  std::optional<std::uint64_t> status_drops;
  std::optional<std::uint64_t> alarm_drops;
  session.mcap().for_each_message(Order::kLogTime, [&](const MessageView& m) {
    if (m.channel->topic == topic::kStatus) status_drops = recording_drops(m);
    if (m.channel->topic == topic::kAlarms) alarm_drops = recording_drops(m);
  });
  EXPECT_EQ(status_drops, std::optional<std::uint64_t>(17));
  EXPECT_EQ(alarm_drops, std::nullopt);  // an Alarm has no recording_drops
}

TEST(SessionReader, RecordedConfigurationWithOverrides) {
  const TempDir dir;
  (void)write_session(dir / "s.mcap");
  const SessionReader session = SessionReader::open(dir / "s.mcap");
  const std::optional<config::LoadedConfig> as_recorded = recorded_config(session);
  ASSERT_TRUE(as_recorded.has_value());
  EXPECT_EQ(as_recorded->config.gains().kps(), 700.0);
  EXPECT_EQ(as_recorded->source_name, (dir / "s.mcap").string() + " (/config)");
  const std::optional<config::LoadedConfig> changed = recorded_config(session, {"gains.kps=800"});
  ASSERT_TRUE(changed.has_value());
  EXPECT_EQ(changed->config.gains().kps(), 800.0);
  EXPECT_EQ(changed->config.gains().kpm(), 600.0);
  EXPECT_THROW((void)recorded_config(session, {"gains.kps=-1"}), config::ConfigError);
}

TEST(SessionReader, AMissingChannel) {
  const TempDir dir;
  {
    const std::unique_ptr<SessionSink> sink = make_session_recorder_at(dir / "m.mcap");
    v1::Telemetry t;
    t.set_session_id(5);
    *t.add_cycles() = cycle_proto(1, 1000, v1::ENGAGED, 1.0);
    record(*sink, topic::kMasterTelemetry, 10, t);
  }
  const SessionReader session = SessionReader::open(dir / "m.mcap");
  EXPECT_EQ(session.cycles(true).size(), 1U);
  try {
    (void)session.cycles(false);
    FAIL() << "no slave channel: expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), (dir / "m.mcap").string() +
                                         ": no channel '/slave/telemetry' (channels: "
                                         "/master/telemetry)");
  }
  EXPECT_FALSE(session.config().has_value());
  EXPECT_FALSE(recorded_config(session).has_value());
  EXPECT_THROW((void)recorded_config(session, {"gains.kps=800"}), std::runtime_error);
  EXPECT_TRUE(session.reports().empty());
  EXPECT_TRUE(session.alarms().empty());
}

TEST(SessionReader, AModeThisVersionDoesNotKnowReadsAsDisarmed) {
  const TempDir dir;
  {
    const std::unique_ptr<SessionSink> sink = make_session_recorder_at(dir / "u.mcap");
    v1::Telemetry t;
    *t.add_cycles() = cycle_proto(1, 1000, v1::NODE_MODE_UNSPECIFIED, 1.0);
    *t.add_cycles() = cycle_proto(2, 2000, static_cast<v1::NodeMode>(42), 2.0);
    record(*sink, topic::kSlaveTelemetry, 10, t);
  }
  const std::vector<RecordedCycle> cycles = SessionReader::open(dir / "u.mcap").cycles(false);
  ASSERT_EQ(cycles.size(), 2U);
  EXPECT_EQ(cycles[0].cycle.mode, node::Mode::kDisarmed);
  EXPECT_EQ(cycles[1].cycle.mode, node::Mode::kDisarmed);
}

TEST(SessionReader, MessagesOfAnotherTypeOnAChannelAreRefused) {
  const TempDir dir;
  {
    const std::unique_ptr<SessionSink> sink = make_session_recorder_at(dir / "w.mcap");
    v1::Alarm a;
    a.set_kind("x");
    record(*sink, topic::kMasterTelemetry, 10, a);
  }
  const SessionReader session = SessionReader::open(dir / "w.mcap");
  try {
    (void)session.cycles(true);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("carries teleop.v1.Alarm, not teleop.v1.Telemetry"),
              std::string::npos)
        << e.what();
  }
}

TEST(SessionReader, FilesThatAreNotSessions) {
  const TempDir dir;
  try {
    (void)SessionReader::open(dir / "missing.mcap");
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), (dir / "missing.mcap").string() + ": no such file");
  }
  {
    std::ofstream f(dir / "text.mcap");
    f << "not an mcap file at all\n";
  }
  EXPECT_FALSE(is_mcap_file(dir / "text.mcap"));
  EXPECT_THROW((void)SessionReader::open(dir / "text.mcap"), std::runtime_error);

  // Cut short: the message says how to recover it.
  (void)write_session(dir / "s.mcap");
  EXPECT_TRUE(is_mcap_file(dir / "s.mcap"));
  fs::resize_file(dir / "s.mcap", fs::file_size(dir / "s.mcap") - 20);
  try {
    (void)SessionReader::open(dir / "s.mcap");
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("teleopctl replay --recover OUT.mcap"), std::string::npos)
        << e.what();
  }
}

// The loop statistics of a node's telemetry: gaps, restarts and skipped deadlines counted as
// the test lays them out.
TEST(NodeTelemetryStats, GapsRestartsAndOverruns) {
  constexpr std::int64_t kMs = 1'000'000;
  v1::Telemetry a;
  a.set_session_id(1);
  a.mutable_loop()->set_period_s(1e-3);
  // Sequences 1, 2, 3 with 3 three periods after 2 (2 deadlines skipped), then 6 (4 and 5
  // missing).
  *a.add_cycles() = cycle_proto(1, 1 * kMs, v1::ENGAGED, 0.0);
  *a.add_cycles() = cycle_proto(2, 2 * kMs, v1::ENGAGED, 0.0);
  *a.add_cycles() = cycle_proto(3, 5 * kMs, v1::ENGAGED, 0.0);
  *a.add_cycles() = cycle_proto(6, 6 * kMs, v1::ENGAGED, 0.0);
  a.mutable_cycles(0)->set_wakeup_latency_ns(10'000);
  a.mutable_cycles(1)->set_wakeup_latency_ns(60'000);
  a.mutable_cycles(2)->set_wakeup_latency_ns(7'000'000);
  a.mutable_cycles(3)->set_wakeup_latency_ns(100'000);
  v1::Telemetry b;
  b.set_session_id(2);  // a restart
  b.mutable_loop()->set_period_s(1e-3);
  b.set_cycles_dropped(4);
  *b.add_cycles() = cycle_proto(1, 1500 * kMs, v1::SAFE, 0.0);
  b.mutable_cycles(0)->set_wakeup_latency_ns(-5);

  NodeTelemetryStats s;
  s.add(a);
  s.add(b);
  EXPECT_EQ(s.messages, 2U);
  EXPECT_EQ(s.cycles, 5U);
  EXPECT_EQ(s.missing, 2U);
  EXPECT_EQ(s.restarts, 1U);
  EXPECT_EQ(s.out_of_order, 0U);
  EXPECT_EQ(s.cycles_dropped, 4U);
  EXPECT_EQ(s.first_sequence, 1U);
  EXPECT_EQ(s.last_sequence, 1U);
  EXPECT_EQ(s.modes.at("ENGAGED"), 4U);
  EXPECT_EQ(s.modes.at("SAFE"), 1U);

  const std::optional<WakeupLatencySummary> w = s.wakeup_latency();
  ASSERT_TRUE(w.has_value());
  EXPECT_EQ(w->negative, 1U);
  EXPECT_EQ(w->max_us, 7000.0);
  EXPECT_EQ(w->p50_us, 60.0);  // nearest rank 3 of (-0.005, 10, 60, 100, 7000) us
  ASSERT_EQ(w->histogram.size(), 8U);
  EXPECT_EQ(w->histogram[0].from_us, 0);
  EXPECT_EQ(w->histogram[0].to_us, std::optional<std::int64_t>(50));
  EXPECT_EQ(w->histogram[0].cycles, 1U);  // 10 us
  EXPECT_EQ(w->histogram[1].cycles, 1U);  // 60 us
  EXPECT_EQ(w->histogram[2].cycles, 1U);  // 100 us
  EXPECT_EQ(w->histogram[7].from_us, 5000);
  EXPECT_EQ(w->histogram[7].to_us, std::nullopt);
  EXPECT_EQ(w->histogram[7].cycles, 1U);  // 7000 us

  const OverrunSummary o = s.overruns();
  EXPECT_EQ(o.total, 2U);
  EXPECT_EQ(o.seconds, 2U);  // seconds 0 and 1 of the node's clock
  EXPECT_EQ(o.worst_second, 2U);
  ASSERT_EQ(o.seconds_histogram.size(), 5U);
  EXPECT_EQ(o.seconds_histogram[0].seconds, 1U);  // second 1: none skipped
  EXPECT_EQ(o.seconds_histogram[2].from, 2U);
  EXPECT_EQ(o.seconds_histogram[2].to, std::optional<std::uint64_t>(9));
  EXPECT_EQ(o.seconds_histogram[2].seconds, 1U);  // second 0: 2 skipped
}

}  // namespace
}  // namespace teleop::record
