// The session library with n task-space axes (issue 18; common/session/session_reader.hpp
// cycles_axes, session_stats.hpp per-axis summary): sessions written here through the live
// session recorder, every value read back checked against the value written (per axis a
// distinct number derived from the cycle and the axis), the per-axis ranges against their hand
// computation, and records the codec must refuse reported naming the file, topic and sequence.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
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

// Axis i of cycle k: position (k + 1) * (i + 1) mm, velocity 10 * that, force -(k + 2i) N,
// command 0.5 k - i N, peer position -position.
double pos(int k, int i) { return 1e-3 * (k + 1) * (i + 1); }
double force(int k, int i) { return -(k + 2.0 * i); }
double command(int k, int i) { return 0.5 * k - i; }

// An n-axis cycle as the protocol carries it (telemetry.proto: axes and one entry per axis),
// written field by field here, not through the codec.
v1::CycleRecord cycle_axes(int k, int axes) {
  v1::CycleRecord c;
  c.set_sequence(static_cast<std::uint64_t>(100 + k));
  c.set_sample_time_ns(1'000'000LL * (k + 1));
  c.set_mode(v1::ENGAGED);
  c.set_wakeup_latency_ns(30'000 + k);
  c.set_axes(static_cast<std::uint32_t>(axes));
  for (int i = 0; i < axes; ++i) {
    c.add_positions_m(pos(k, i));
    c.add_velocities_m_per_s(10.0 * pos(k, i));
    c.add_forces_n(force(k, i));
    c.add_commands_n(command(k, i));
    c.add_peer_positions_m(-pos(k, i));
  }
  c.set_fixture_penetration_m(1e-4 * k);
  return c;
}

void record(SessionSink& sink, std::string_view topic, std::int64_t log_time_ns,
            const google::protobuf::Message& m) {
  sink.record(topic, m.GetDescriptor()->full_name(), log_time_ns, m.SerializeAsString());
}

// `messages` telemetry messages of 5 cycles each on both nodes, `axes` axes; `bad` (if set)
// replaces the slave's cycle of that index.
void write_session(const fs::path& file, int axes, int cycles, const v1::CycleRecord* bad = nullptr,
                   int bad_index = -1) {
  const std::unique_ptr<SessionSink> sink = make_session_recorder_at(file);
  for (int start = 0; start < cycles; start += 5) {
    v1::Telemetry m;
    v1::Telemetry s;
    m.set_session_id(7);
    s.set_session_id(8);
    m.mutable_loop()->set_period_s(1e-3);
    s.mutable_loop()->set_period_s(1e-3);
    for (int k = start; k < start + 5 && k < cycles; ++k) {
      *m.add_cycles() = cycle_axes(k, axes);
      *s.add_cycles() = (bad != nullptr && k == bad_index) ? *bad : cycle_axes(k, axes);
    }
    record(*sink, topic::kMasterTelemetry, 1000 + start, m);
    record(*sink, topic::kSlaveTelemetry, 1001 + start, s);
  }
}

TEST(SessionAxes, ThreeAxisCyclesReadBackPerAxisAsWritten) {
  const TempDir dir;
  write_session(dir / "a.mcap", 3, 12);
  const SessionReader session = SessionReader::open(dir / "a.mcap");
  for (const bool master : {true, false}) {
    const std::vector<RecordedCycleAxes> cycles = session.cycles_axes(master);
    ASSERT_EQ(cycles.size(), 12U);
    for (int k = 0; k < 12; ++k) {
      const node::CycleRecordAxes& c = cycles[static_cast<std::size_t>(k)].cycle;
      EXPECT_EQ(cycles[static_cast<std::size_t>(k)].session_id, master ? 7U : 8U);
      EXPECT_EQ(c.sequence, static_cast<std::uint64_t>(100 + k));
      EXPECT_EQ(c.sample_time_ns, 1'000'000LL * (k + 1));
      EXPECT_EQ(c.mode, node::Mode::kEngaged);
      ASSERT_EQ(c.axes, 3);
      EXPECT_EQ(c.fixture_penetration_m, 1e-4 * k);
      for (int i = 0; i < 3; ++i) {
        const auto a = static_cast<std::size_t>(i);
        EXPECT_EQ(c.position_m[a], pos(k, i)) << k << "," << i;
        EXPECT_EQ(c.velocity_m_per_s[a], 10.0 * pos(k, i));
        EXPECT_EQ(c.force_N[a], force(k, i));
        EXPECT_EQ(c.command_N[a], command(k, i));
        EXPECT_EQ(c.peer_position_m[a], -pos(k, i));
      }
    }
  }
}

// The one-axis read of a 3-axis session would give zeros (the scalars are unset): refused,
// naming the file, topic and the first cycle.
TEST(SessionAxes, TheOneAxisReadRefusesSeveralAxesNamingWhere) {
  const TempDir dir;
  write_session(dir / "a.mcap", 3, 5);
  const SessionReader session = SessionReader::open(dir / "a.mcap");
  try {
    (void)session.cycles(true);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find((dir / "a.mcap").string() + ": /master/telemetry cycle 100 "),
              std::string::npos)
        << what;
    EXPECT_NE(what.find("3 axes"), std::string::npos) << what;
  }
}

// A one-axis session (axes unset, the scalars hold the axis) reads as 1-axis cycles carrying
// the scalars, and the one-axis read gives the same numbers as before.
TEST(SessionAxes, AOneAxisSessionReadsAsOneAxisEitherWay) {
  const TempDir dir;
  {
    const std::unique_ptr<SessionSink> sink = make_session_recorder_at(dir / "one.mcap");
    v1::Telemetry t;
    t.set_session_id(3);
    for (int k = 0; k < 4; ++k) {
      v1::CycleRecord* c = t.add_cycles();
      c->set_sequence(static_cast<std::uint64_t>(k + 1));
      c->set_sample_time_ns(1'000'000LL * k);
      c->set_position_m(pos(k, 0));
      c->set_force_n(force(k, 0) + 0.25);
      c->set_command_n(command(k, 0));
      c->set_peer_position_m(-pos(k, 0));
    }
    record(*sink, topic::kMasterTelemetry, 10, t);
  }
  const SessionReader session = SessionReader::open(dir / "one.mcap");
  const std::vector<RecordedCycleAxes> axes = session.cycles_axes(true);
  const std::vector<RecordedCycle> one = session.cycles(true);
  ASSERT_EQ(axes.size(), 4U);
  ASSERT_EQ(one.size(), 4U);
  for (int k = 0; k < 4; ++k) {
    const auto u = static_cast<std::size_t>(k);
    EXPECT_EQ(axes[u].cycle.axes, 1);
    EXPECT_EQ(axes[u].cycle.position_m[0], pos(k, 0));
    EXPECT_EQ(axes[u].cycle.force_N[0], force(k, 0) + 0.25);
    EXPECT_EQ(axes[u].cycle.command_N[0], command(k, 0));
    EXPECT_EQ(axes[u].cycle.peer_position_m[0], -pos(k, 0));
    EXPECT_EQ(one[u].cycle.position_m, pos(k, 0));
    EXPECT_EQ(one[u].cycle.force_N, force(k, 0) + 0.25);
    EXPECT_EQ(one[u].cycle.command_N, command(k, 0));
    EXPECT_EQ(one[u].session_id, 3U);
  }
  NodeTelemetryStats stats;
  for (const MessageView& m : session.messages_on(topic::kMasterTelemetry)) {
    stats.add(session.decode<v1::Telemetry>(m));
  }
  EXPECT_EQ(stats.axes, 1);
  ASSERT_EQ(stats.per_axis.size(), 1U);
  EXPECT_EQ(stats.per_axis[0].min_position_m, pos(0, 0));
  EXPECT_EQ(stats.per_axis[0].max_position_m, pos(3, 0));
  EXPECT_EQ(stats.refused, 0U);
}

// The one-axis read refuses a malformed one-axis record (axes = 1 with per-axis fields) the same
// way, naming the file, topic and its sequence.
TEST(SessionAxes, TheOneAxisReadRefusesAMalformedRecordNamingWhere) {
  const TempDir dir;
  {
    const std::unique_ptr<SessionSink> sink = make_session_recorder_at(dir / "m.mcap");
    v1::Telemetry t;
    t.add_cycles()->set_sequence(1);
    v1::CycleRecord* bad = t.add_cycles();
    bad->set_sequence(2);
    bad->set_axes(1);
    bad->add_positions_m(0.5);
    record(*sink, topic::kMasterTelemetry, 10, t);
  }
  try {
    (void)SessionReader::open(dir / "m.mcap").cycles(true);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()).rfind(
                  (dir / "m.mcap").string() + ": /master/telemetry cycle 2 (log time 10 ns): ", 0),
              0U)
        << e.what();
  }
}

// Records the codec refuses: more axes than kMaxAxes, and an axis count its per-axis fields do
// not match. Each read reports the file, topic and the record's sequence, never crashes.
TEST(SessionAxes, ARecordTheCodecRefusesIsAnErrorNamingFileTopicAndSequence) {
  v1::CycleRecord too_many = cycle_axes(3, 3);
  too_many.set_axes(9);
  v1::CycleRecord short_field = cycle_axes(3, 3);
  short_field.mutable_forces_n()->RemoveLast();
  int which = 0;
  for (const v1::CycleRecord* bad : {&too_many, &short_field}) {
    SCOPED_TRACE(which);
    const TempDir dir;
    const fs::path file = dir / ("bad" + std::to_string(which++) + ".mcap");
    write_session(file, 3, 10, bad, 3);
    const SessionReader session = SessionReader::open(file);
    EXPECT_EQ(session.cycles_axes(true).size(), 10U);  // the master's are fine
    {
      try {
        (void)session.cycles_axes(false);
        FAIL() << "expected an error";
      } catch (const std::runtime_error& e) {
        const std::string what = e.what();
        EXPECT_EQ(
            what.rfind(file.string() + ": /slave/telemetry cycle 103 (log time 1001 ns): ", 0), 0U)
            << what;
        EXPECT_NE(what.find("refuses"), std::string::npos) << what;
      }
    }
    NodeTelemetryStats stats;
    for (const MessageView& m : session.messages_on(topic::kSlaveTelemetry)) {
      stats.add(session.decode<v1::Telemetry>(m));
    }
    EXPECT_EQ(stats.cycles, 10U);
    EXPECT_EQ(stats.refused, 1U);
    EXPECT_EQ(stats.first_refused_sequence, 103U);
    EXPECT_EQ(stats.axes, 3);
    EXPECT_EQ(stats.missing, 0U);
  }
}

// The per-axis summary of 12 three-axis cycles, by hand: position of axis i from
// 1 mm (i + 1) (k = 0) to 12 mm (i + 1) (k = 11); |force| largest at k = 11: 11 + 2i N;
// |command| largest at k = 0 (i N) or k = 11 (5.5 - i N): 5.5, 4.5, 3.5 for i = 0, 1, 2.
TEST(SessionAxes, StatsCountAxesAndSumUpEachAxis) {
  const TempDir dir;
  write_session(dir / "a.mcap", 3, 12);
  const SessionReader session = SessionReader::open(dir / "a.mcap");
  NodeTelemetryStats stats;
  for (const MessageView& m : session.messages_on(topic::kMasterTelemetry)) {
    stats.add(session.decode<v1::Telemetry>(m));
  }
  EXPECT_EQ(stats.cycles, 12U);
  EXPECT_EQ(stats.axes, 3);
  EXPECT_EQ(stats.axes_changes, 0U);
  EXPECT_EQ(stats.refused, 0U);
  ASSERT_EQ(stats.per_axis.size(), 3U);
  const double max_command[] = {5.5, 4.5, 3.5};
  for (int i = 0; i < 3; ++i) {
    const AxisSummary& a = stats.per_axis[static_cast<std::size_t>(i)];
    EXPECT_DOUBLE_EQ(a.min_position_m, 1e-3 * (i + 1)) << i;
    EXPECT_DOUBLE_EQ(a.max_position_m, 12e-3 * (i + 1)) << i;
    EXPECT_DOUBLE_EQ(a.max_abs_force_N, 11.0 + 2.0 * i) << i;
    EXPECT_DOUBLE_EQ(a.max_abs_command_N, max_command[i]) << i;
  }
  // A node restarted with 2 axes: one change, the summary keeps 3 axes.
  v1::Telemetry t;
  *t.add_cycles() = cycle_axes(20, 2);
  stats.add(t);
  EXPECT_EQ(stats.axes_changes, 1U);
  EXPECT_EQ(stats.axes, 3);
}

}  // namespace
}  // namespace teleop::record
