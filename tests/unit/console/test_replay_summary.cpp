// The summary stream of `teleopctl replay` for a session whose /config is missing or does not
// describe the teleoperator: the papers' paddles stand in (said on stderr for a bad one), and
// the stream still shows the recorded telemetry -- the node's position as recorded.
#include <gtest/gtest.h>

#include <sstream>
#include <string>

#include "common/config/config_loader.hpp"
#include "supervisor/teleopctl/replay_supervision.hpp"

namespace teleop::ctl {
namespace {

std::string telemetry_bytes(double position_m) {
  v1::Telemetry t;
  t.set_session_id(7);
  t.set_mode(v1::ENGAGED);
  v1::CycleRecord* c = t.add_cycles();
  c->set_sequence(1);
  c->set_sample_time_ns(1'000'000'000);
  c->set_mode(v1::ENGAGED);
  c->set_position_m(position_m);
  return t.SerializeAsString();
}

TEST(ReplaySummary, WithoutAConfigurationThePaddlesStandInAndTheRecordedCyclesShow) {
  const std::string master = telemetry_bytes(0.0125);
  std::ostringstream err;
  // A slave message that does not decode (truncated, garbage) is left out, nothing more.
  const std::string garbage("\xff\xff\xff\x0a\x7f", 5);
  ReplaySummary summary(std::nullopt,
                        {{ReplaySummary::kMaster, 1'000'000'000, master},
                         {ReplaySummary::kSlave, 1'000'000'000, garbage},
                         {ReplaySummary::kReport, 1'000'000'000, garbage}},
                        err);
  EXPECT_EQ(err.str(), "");
  summary.advance_to(1'000'000'000);
  const v1::SupervisorStatus st = summary.status();
  EXPECT_EQ(st.source(), "replay");
  EXPECT_FALSE(st.client_may_command());
  EXPECT_FALSE(st.has_report());
  EXPECT_EQ(st.master().position_m(), 0.0125);
  EXPECT_TRUE(st.master_alive());
  EXPECT_FALSE(st.slave_alive());
}

TEST(ReplaySummary, AConfigurationThatDoesNotDescribeTheTeleoperatorIsSaidAndReplaced) {
  // Parsed, never validated: a negative mass, as a damaged or hand-edited /config may hold.
  const config::LoadedConfig bad = config::parse_config_text(
      "sample_rate_hz: 1000 master { device { mass_kg: -1 } }", "recorded /config");
  const std::string master = telemetry_bytes(-0.003);
  std::ostringstream err;
  ReplaySummary summary(bad, {{ReplaySummary::kMaster, 5, master}}, err);
  EXPECT_NE(err.str().find("does not describe the teleoperator"), std::string::npos) << err.str();
  EXPECT_NE(err.str().find("mass_kg"), std::string::npos) << err.str();
  summary.advance_to(5);
  EXPECT_EQ(summary.status().master().position_m(), -0.003);
}

}  // namespace
}  // namespace teleop::ctl
