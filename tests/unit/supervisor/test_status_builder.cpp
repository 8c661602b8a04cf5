// The summary stream's builder (issue 6): NodeSummaryBuilder, feed_monitors, read_monitors.
// Every expected value is worked out here from the inputs (closed forms, hand sums, or a direct
// scan of the samples the test generated), never read back from the code under test.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <string>
#include <vector>

#include "supervisor/core/monitors.hpp"
#include "supervisor/core/status_builder.hpp"

namespace teleop::supervisor {
namespace {

constexpr std::int64_t kMs = 1'000'000;
constexpr std::int64_t kS = 1'000'000'000;

v1::CycleRecord cycle(std::int64_t t_ns, double x, double v = 0.0, double f = 0.0,
                      double command = 0.0, v1::NodeMode mode = v1::ENGAGED) {
  v1::CycleRecord c;
  c.set_sample_time_ns(t_ns);
  c.set_position_m(x);
  c.set_velocity_m_per_s(v);
  c.set_force_n(f);
  c.set_command_n(command);
  c.set_mode(mode);
  return c;
}

v1::NodeSummary summary(const NodeSummaryBuilder& b, std::int64_t now_ns,
                        const MonitorReadings& m = {}) {
  v1::NodeSummary out;
  b.fill(out, now_ns, m);
  return out;
}

// Sends `cycles` to the builder in telemetry messages of `batch` cycles each.
void send_in_batches(NodeSummaryBuilder& b, const std::vector<v1::CycleRecord>& cycles,
                     std::size_t batch) {
  for (std::size_t i = 0; i < cycles.size(); i += batch) {
    v1::Telemetry t;
    const std::size_t end = std::min(cycles.size(), i + batch);
    for (std::size_t k = i; k < end; ++k) *t.add_cycles() = cycles[k];
    t.set_sent_time_ns(cycles[end - 1].sample_time_ns());
    b.add(t, cycles[end - 1].sample_time_ns());
  }
}

// ---------------------------------------------------------------------------------- loop rate

TEST(StatusBuilderLoopRate, CyclesEveryMillisecondForTwoSecondsGiveOneKilohertz) {
  NodeSummaryBuilder b(true, 0.01, 1000.0);
  const std::int64_t t0 = 3 * kS + 7;  // arbitrary, not aligned
  v1::Telemetry t;
  for (std::int64_t k = 0; k <= 2000; ++k) *t.add_cycles() = cycle(t0 + k * kMs, 0.0);
  b.add(t, t0 + 2 * kS);
  EXPECT_NEAR(summary(b, t0 + 2 * kS).loop_rate_hz(), 1000.0, 1000.0 * 1e-9);
}

TEST(StatusBuilderLoopRate, EveryTenthCycleMissingCountsTheCyclesOfTheLastSecond) {
  NodeSummaryBuilder b(true, 0.01, 1000.0);
  const std::int64_t t0 = 11 * kS;
  std::vector<std::int64_t> stamps;
  for (std::int64_t k = 0; k <= 2000; ++k) {
    if (k % 10 == 9) continue;  // an overrun skipped this deadline
    stamps.push_back(t0 + k * kMs);
  }
  std::vector<v1::CycleRecord> cycles;
  for (const std::int64_t s : stamps) cycles.push_back(cycle(s, 0.0));
  send_in_batches(b, cycles, stamps.size());

  // Independently: the cycles within [newest - 1 s, newest], and the rate as (count - 1)
  // intervals over the time between the first and the newest of them.
  const std::int64_t newest = stamps.back();
  std::int64_t count = 0;
  std::int64_t first = newest;
  for (const std::int64_t s : stamps) {
    if (s >= newest - kS) {
      ++count;
      first = std::min(first, s);
    }
  }
  // Closed form as a cross-check of the scan: k in [1000, 2000] is 1001 deadlines, 100 of them
  // (1009, 1019, ..., 1999) skipped: 901 cycles, 900 intervals over exactly 1 s.
  ASSERT_EQ(count, 901);
  ASSERT_EQ(newest - first, kS);
  const double expected =
      static_cast<double>(count - 1) * 1e9 / static_cast<double>(newest - first);
  EXPECT_NEAR(summary(b, newest).loop_rate_hz(), expected, expected * 1e-9);
  EXPECT_NEAR(summary(b, newest).loop_rate_hz(), 900.0, 900.0 * 1e-9);
}

TEST(StatusBuilderLoopRate, CyclesArrivingInSeveralBatchesGiveTheSameRate) {
  NodeSummaryBuilder b(false, 0.01, 1000.0);
  const std::int64_t t0 = 42 * kS + 123'456;
  std::vector<v1::CycleRecord> cycles;
  for (std::int64_t k = 0; k <= 2000; ++k) {
    cycles.push_back(cycle(t0 + k * kMs, 1e-6 * static_cast<double>(k)));
  }
  send_in_batches(b, cycles, 37);  // 37 does not divide 2001: a short last batch
  const v1::NodeSummary s = summary(b, t0 + 2 * kS);
  EXPECT_NEAR(s.loop_rate_hz(), 1000.0, 1000.0 * 1e-9);
  EXPECT_DOUBLE_EQ(s.position_m(), 1e-6 * 2000.0);  // the newest cycle of the last batch
}

TEST(StatusBuilderLoopRate, ACycleThatIsNotNewerIsIgnored) {
  NodeSummaryBuilder b(true, 0.01, 1000.0);
  const std::int64_t t0 = 5 * kS;
  std::vector<v1::CycleRecord> cycles;
  for (std::int64_t k = 0; k <= 2000; ++k) cycles.push_back(cycle(t0 + k * kMs, 0.001));
  send_in_batches(b, cycles, 100);
  const std::int64_t newest = t0 + 2000 * kMs;

  // A duplicate of the newest timestamp and an older one, both with a position never seen.
  v1::Telemetry dup;
  *dup.add_cycles() = cycle(newest, 0.5, 9.0, 9.0, 9.0);
  *dup.add_cycles() = cycle(newest - kMs / 2, 0.7, 9.0, 9.0, 9.0);
  b.add(dup, newest + kMs);

  const v1::NodeSummary s = summary(b, newest + kMs);
  // Counted, the duplicate would make 1002 stamps over 1 s: 1001 Hz.
  EXPECT_NEAR(s.loop_rate_hz(), 1000.0, 1000.0 * 1e-9);
  EXPECT_DOUBLE_EQ(s.position_m(), 0.001);
  EXPECT_DOUBLE_EQ(s.velocity_m_per_s(), 0.0);
  const v1::Trace& tr = s.position_trace_m();
  ASSERT_GT(tr.max_size(), 0);
  for (int i = 0; i < tr.max_size(); ++i) EXPECT_FLOAT_EQ(tr.max(i), 0.001f) << i;
}

// ------------------------------------------------------------------------------------ overruns

// The node's overrun counter at message j: starts at 42 (the node had overruns before we
// listened) and grows by 2 on every message j = 3 (mod 7) and by 5 more on every 50th.
std::vector<std::uint64_t> overrun_pattern(int n, std::uint64_t start) {
  std::vector<std::uint64_t> ov(static_cast<std::size_t>(n));
  ov[0] = start;
  for (int j = 1; j < n; ++j) {
    std::uint64_t inc = 0;
    if (j % 7 == 3) inc += 2;
    if (j % 50 == 0) inc += 5;
    ov[static_cast<std::size_t>(j)] = ov[static_cast<std::size_t>(j - 1)] + inc;
  }
  return ov;
}

v1::Telemetry overrun_message(std::int64_t sent_ns, std::uint64_t overruns) {
  v1::Telemetry t;
  t.set_sent_time_ns(sent_ns);
  t.mutable_loop()->set_overruns(overruns);
  return t;
}

TEST(StatusBuilderOverruns, CountsTheIncreaseOverTheLastMinute) {
  NodeSummaryBuilder b(true, 0.01, 1000.0);
  // Messages every 100 ms for 3 minutes (j = 0..1800), on the node's clock; the supervisor's
  // clock is offset (overruns are read on the node's sent time, not the receive time).
  constexpr int kMessages = 1801;
  const std::vector<std::uint64_t> ov = overrun_pattern(kMessages, 42);
  const std::int64_t t0 = 9 * kS + 3;
  const std::int64_t clock_offset = 500 * kS;
  int nontrivial_bands = 0;
  for (int j = 0; j < kMessages; ++j) {
    const auto uj = static_cast<std::size_t>(j);
    const std::int64_t sent = t0 + j * 100 * kMs;
    b.add(overrun_message(sent, ov[uj]), sent + clock_offset);
    const std::uint64_t got = summary(b, sent + clock_offset).overruns_last_minute();
    if (j < 600) {
      // Less than a minute heard: everything since the first message.
      EXPECT_EQ(got, ov[uj] - ov[0]) << "j=" << j;
      continue;
    }
    // The builder keeps its history at 0.5 s granularity (one entry per >= 0.5 s of the
    // node's clock), so its baseline is the entry at or just before now - 60 s: at most 0.5 s
    // (5 messages) older. The count is therefore between the increase over exactly 60 s
    // (600 messages back) and over 60.5 s (605 messages back).
    const std::uint64_t exact = ov[uj] - ov[uj - 600];
    const std::uint64_t widest = ov[uj] - ov[uj >= 605 ? uj - 605 : 0];
    if (widest > exact) ++nontrivial_bands;
    EXPECT_GE(got, exact) << "j=" << j;
    EXPECT_LE(got, widest) << "j=" << j;
  }
  EXPECT_GT(nontrivial_bands, 0);  // the band was not always a single value
  // At the end, by hand: over j in (1200, 1800], j = 3 (mod 7) occurs 85 times (1207, ...,
  // 1795) and j = 0 (mod 50) 12 times (1250, ..., 1800): 2 * 85 + 5 * 12 = 230 over exactly
  // 60 s. A baseline up to 0.5 s older also takes in j = 1196..1200, of which 1200 is both
  // 3 (mod 7) and a multiple of 50: + 7. So 230..237.
  EXPECT_EQ(ov[1800] - ov[1200], 230U);
  EXPECT_EQ(ov[1800] - ov[1195], 237U);
  const std::uint64_t end = summary(b, t0 + 180 * kS + clock_offset).overruns_last_minute();
  EXPECT_GE(end, 230U);
  EXPECT_LE(end, 237U);
}

TEST(StatusBuilderOverruns, ResetStartsOver) {
  NodeSummaryBuilder b(true, 0.01, 1000.0);
  const std::vector<std::uint64_t> ov = overrun_pattern(301, 0);
  for (int j = 0; j < 301; ++j) {
    b.add(overrun_message(100 * kS + j * 100 * kMs, ov[static_cast<std::size_t>(j)]),
          100 * kS + j * 100 * kMs);
  }
  ASSERT_GT(summary(b, 130 * kS).overruns_last_minute(), 0U);

  b.reset();
  EXPECT_TRUE(b.empty());
  const v1::NodeSummary cleared = summary(b, 130 * kS);
  EXPECT_FALSE(cleared.alive());
  EXPECT_EQ(cleared.overruns_last_minute(), 0U);

  // A new session of the node: its clock is earlier than before, its counter at 1000 and
  // rising by one every message. Nothing from before the reset may count.
  for (int j = 0; j < 100; ++j) {
    const std::int64_t sent = 2 * kS + j * 100 * kMs;
    b.add(overrun_message(sent, 1000U + static_cast<std::uint64_t>(j)), 200 * kS + j * 100 * kMs);
    EXPECT_EQ(summary(b, 200 * kS + j * 100 * kMs).overruns_last_minute(),
              static_cast<std::uint64_t>(j))
        << "j=" << j;
  }
}

// --------------------------------------------------------------------------- fixture penetration

v1::Telemetry one_cycle(std::int64_t t_ns, double x) {
  v1::Telemetry t;
  t.set_sent_time_ns(t_ns);
  *t.add_cycles() = cycle(t_ns, x);
  return t;
}

TEST(StatusBuilderPenetration, MasterFixtureAtOneCentimetre) {
  NodeSummaryBuilder b(true, 0.01, 1000.0);
  b.add(one_cycle(kS, 0.013), kS);
  v1::NodeSummary s = summary(b, kS);
  EXPECT_NEAR(s.fixture_penetration_m(), 0.003, 1e-15);  // 0.013 - 0.010
  ASSERT_EQ(s.penetration_trace_m().max_size(), 1);
  EXPECT_NEAR(s.penetration_trace_m().max(0), 0.003f, 1e-9);

  b.add(one_cycle(2 * kS, 0.005), 2 * kS);  // outside the wall
  s = summary(b, 2 * kS);
  EXPECT_EQ(s.fixture_penetration_m(), 0.0);
  EXPECT_EQ(s.penetration_trace_m().max(s.penetration_trace_m().max_size() - 1), 0.0f);
  EXPECT_EQ(s.penetration_trace_m().min(s.penetration_trace_m().min_size() - 1), 0.0f);
}

// The penetration in the newest trace bucket (each message here lands in a bucket of its own).
float newest_traced_penetration(const v1::NodeSummary& s) {
  const v1::Trace& tr = s.penetration_trace_m();
  EXPECT_GT(tr.max_size(), 0);
  EXPECT_EQ(tr.min(tr.min_size() - 1), tr.max(tr.max_size() - 1));  // one sample per bucket
  return tr.max(tr.max_size() - 1);
}

TEST(StatusBuilderPenetration, SlaveSideUsesTheActiveSlaveStiffness) {
  // Configured: a 1000 N/m wall at 1 cm on the slave.
  NodeSummaryBuilder b(false, 0.01, 1000.0);

  // In force: no slave wall (the master's is stiff, and must not be taken for the slave's).
  v1::Telemetry t = one_cycle(kS, 0.02);
  t.mutable_active()->set_slave_fixture_stiffness_n_per_m(0.0);
  t.mutable_active()->set_master_fixture_stiffness_n_per_m(1000.0);
  b.add(t, kS);
  v1::NodeSummary s = summary(b, kS);
  EXPECT_EQ(s.fixture_penetration_m(), 0.0);  // 1 cm past where a wall would be
  EXPECT_EQ(newest_traced_penetration(s), 0.0f);

  // In force: a 500 N/m slave wall, none on the master.
  t = one_cycle(2 * kS, 0.02);
  t.mutable_active()->set_slave_fixture_stiffness_n_per_m(500.0);
  t.mutable_active()->set_master_fixture_stiffness_n_per_m(0.0);
  b.add(t, 2 * kS);
  s = summary(b, 2 * kS);
  EXPECT_NEAR(s.fixture_penetration_m(), 0.01, 1e-15);  // 0.02 - 0.01
  EXPECT_NEAR(newest_traced_penetration(s), 0.01, 1e-9);

  // No parameters in the message: the configured 1000 N/m.
  b.add(one_cycle(3 * kS, 0.0125), 3 * kS);
  s = summary(b, 3 * kS);
  EXPECT_NEAR(s.fixture_penetration_m(), 0.0025, 1e-15);
  EXPECT_NEAR(newest_traced_penetration(s), 0.0025, 1e-9);
}

TEST(StatusBuilderPenetration, NoConfiguredStiffnessMeansNoFixture) {
  NodeSummaryBuilder b(true, 0.01, 0.0);
  b.add(one_cycle(kS, 0.05), kS);
  EXPECT_EQ(summary(b, kS).fixture_penetration_m(), 0.0);
  EXPECT_EQ(summary(b, kS).penetration_trace_m().max(0), 0.0f);
}

// -------------------------------------------------------------------------------------- traces

struct MinMax {
  float min;
  float max;
};

// Per bucket of 50 consecutive 1 kHz samples (0.05 s, aligned to the node clock's zero since
// the stream starts on a bucket boundary), the min and max of the float-rounded values.
std::vector<MinMax> bucket_extremes(const std::vector<double>& v, std::size_t first_bucket,
                                    std::size_t buckets) {
  std::vector<MinMax> out;
  for (std::size_t i = first_bucket; i < first_bucket + buckets; ++i) {
    float lo = static_cast<float>(v[50 * i]);
    float hi = lo;
    for (std::size_t k = 50 * i; k < 50 * i + 50; ++k) {
      lo = std::min(lo, static_cast<float>(v[k]));
      hi = std::max(hi, static_cast<float>(v[k]));
    }
    out.push_back({lo, hi});
  }
  return out;
}

TEST(StatusBuilderTraces, SineOverTenSecondsKeepsTheLastFiveInHundredBuckets) {
  constexpr double kA = 1e-3;
  constexpr double kF = 1.3;     // Hz
  constexpr double kP = 0.0005;  // the wall, inside the swing
  NodeSummaryBuilder b(true, kP, 800.0, 5.0, 0.05);
  const std::int64_t t0 = 1000 * kS;  // a whole number of 50 ms buckets
  constexpr std::size_t kN = 10'000;  // 10 s at 1 kHz
  std::vector<double> x(kN), f(kN), pen(kN);
  std::vector<v1::CycleRecord> cycles;
  for (std::size_t k = 0; k < kN; ++k) {
    const double t = static_cast<double>(k) * 1e-3;
    x[k] = kA * std::sin(2.0 * std::numbers::pi * kF * t);
    f[k] = 1.0 + 5.0 * std::cos(2.0 * std::numbers::pi * 0.7 * t);
    pen[k] = x[k] > kP ? x[k] - kP : 0.0;
    cycles.push_back(cycle(t0 + static_cast<std::int64_t>(k) * kMs, x[k], 0.0, f[k]));
  }
  send_in_batches(b, cycles, 100);
  const v1::NodeSummary s = summary(b, t0 + 10 * kS);

  // 10 s is 200 buckets of 50 samples; a 5 s window keeps the last 100 (buckets 100..199).
  const std::vector<MinMax> ex = bucket_extremes(x, 100, 100);
  const std::vector<MinMax> ef = bucket_extremes(f, 100, 100);
  const std::vector<MinMax> ep = bucket_extremes(pen, 100, 100);
  const v1::Trace* traces[] = {&s.position_trace_m(), &s.force_trace_n(), &s.penetration_trace_m()};
  const std::vector<MinMax>* expected[] = {&ex, &ef, &ep};
  for (int j = 0; j < 3; ++j) {
    const v1::Trace& tr = *traces[j];
    EXPECT_DOUBLE_EQ(tr.bucket_s(), 0.05);
    ASSERT_EQ(tr.min_size(), 100) << "trace " << j;
    ASSERT_EQ(tr.max_size(), 100) << "trace " << j;
    for (int i = 0; i < 100; ++i) {
      const MinMax& e = (*expected[j])[static_cast<std::size_t>(i)];
      EXPECT_FLOAT_EQ(tr.min(i), e.min) << "trace " << j << " bucket " << i;
      EXPECT_FLOAT_EQ(tr.max(i), e.max) << "trace " << j << " bucket " << i;
    }
  }
  // The swing reaches past the wall in some buckets and stays clear of it in others.
  EXPECT_GT(*std::max_element(pen.begin(), pen.end()), 0.0);
}

TEST(StatusBuilderTraces, HundredHertzSineShowsItsBandNotAnAlias) {
  // 100 Hz is 5 whole periods per 50 ms bucket: one sample per bucket would draw a constant
  // (the alias at 0 Hz). The min/max per bucket must draw the whole band: every bucket holds
  // 10 samples per period, so its extreme samples are within half a sample spacing (pi/10 of
  // phase) of the peaks: 2A cos(pi/10) <= max - min <= 2A.
  constexpr double kA = 2e-3;
  NodeSummaryBuilder b(false, 0.01, 0.0, 5.0, 0.05);
  const std::int64_t t0 = 50 * kS;
  std::vector<v1::CycleRecord> cycles;
  for (std::int64_t k = 0; k < 10'000; ++k) {
    const double t = static_cast<double>(k) * 1e-3;
    cycles.push_back(cycle(t0 + k * kMs, kA * std::sin(2.0 * std::numbers::pi * 100.0 * t + 0.3)));
  }
  send_in_batches(b, cycles, 100);
  const v1::NodeSummary s = summary(b, t0 + 10 * kS);
  const v1::Trace& tr = s.position_trace_m();
  ASSERT_EQ(tr.max_size(), 100);
  const double lo = 2.0 * kA * std::cos(std::numbers::pi / 10.0);
  for (int i = 0; i < tr.max_size(); ++i) {
    const double band = static_cast<double>(tr.max(i)) - static_cast<double>(tr.min(i));
    EXPECT_GE(band, lo - 1e-9) << i;
    EXPECT_LE(band, 2.0 * kA + 1e-9) << i;
  }
}

// ------------------------------------------------------------------------------ alive and age

TEST(StatusBuilderAlive, AliveWithinHalfASecondAndTheAgeIsExact) {
  NodeSummaryBuilder b(true, 0.01, 1000.0);
  const v1::NodeSummary before = summary(b, 0);
  EXPECT_FALSE(before.alive());
  EXPECT_TRUE(b.empty());

  const std::int64_t received = 77 * kS + 5;
  b.add(one_cycle(3 * kS, 0.0), received);  // node clock unrelated to the receiver's
  EXPECT_FALSE(b.empty());
  v1::NodeSummary s = summary(b, received + 400 * kMs);
  EXPECT_TRUE(s.alive());
  EXPECT_EQ(s.telemetry_age_ns(), 400 * kMs);
  s = summary(b, received + 600 * kMs);
  EXPECT_FALSE(s.alive());
  EXPECT_EQ(s.telemetry_age_ns(), 600 * kMs);
}

// ------------------------------------------------------------------------------ copied fields

TEST(StatusBuilderFields, NewestCycleAndStatusAreCopied) {
  NodeSummaryBuilder b(true, 0.01, 1000.0);
  v1::Telemetry t;
  t.set_mode(v1::ENGAGED);
  t.set_mode_reason("operator engaged");
  t.set_device("sim");
  t.set_sent_time_ns(10 * kS);
  v1::LoopStats* loop = t.mutable_loop();
  loop->set_period_s(0.001);
  loop->set_cycles(12345);
  loop->set_overruns(7);
  loop->set_wakeup_p99_ns(31'000);
  loop->set_wakeup_max_ns(88'000);
  v1::LinkStats* link = t.mutable_link();
  link->set_accepted(1000);
  link->set_lost(3);
  link->set_loss_fraction(0.003);
  link->set_round_trip_ns(2 * kMs);
  link->set_peer_age_ns(kMs / 2);
  v1::RtStatus* rt = t.mutable_rt();
  rt->set_fifo_priority(80);
  rt->set_memory_locked(true);
  rt->set_cpu(3);
  rt->add_refused("cpu_dma_latency: permission denied");
  t.mutable_active()->set_change_id(4);
  t.mutable_active()->set_master_fixture_stiffness_n_per_m(1500.0);
  t.mutable_active()->set_ramp_progress(0.25);
  *t.add_cycles() = cycle(10 * kS - 2 * kMs, 0.001, 0.1, 0.2, 0.3);
  *t.add_cycles() = cycle(10 * kS - 1 * kMs, 0.002, 0.4, 0.5, 0.6);
  *t.add_cycles() = cycle(10 * kS, 0.0123, -0.04, 1.5, -2.25);
  b.add(t, 20 * kS);

  const MonitorReadings m{0.002, 7.5, true, -0.25};
  v1::NodeSummary s = summary(b, 20 * kS, m);
  EXPECT_EQ(s.mode(), v1::ENGAGED);
  EXPECT_EQ(s.mode_reason(), "operator engaged");
  EXPECT_EQ(s.device(), "sim");
  EXPECT_EQ(s.loop().SerializeAsString(), t.loop().SerializeAsString());
  EXPECT_EQ(s.loop().overruns(), 7U);
  EXPECT_EQ(s.loop().wakeup_max_ns(), 88'000);
  EXPECT_EQ(s.link().SerializeAsString(), t.link().SerializeAsString());
  EXPECT_DOUBLE_EQ(s.link().loss_fraction(), 0.003);
  EXPECT_EQ(s.rt().SerializeAsString(), t.rt().SerializeAsString());
  ASSERT_EQ(s.rt().refused_size(), 1);
  EXPECT_EQ(s.rt().refused(0), "cpu_dma_latency: permission denied");
  EXPECT_EQ(s.active().SerializeAsString(), t.active().SerializeAsString());
  EXPECT_DOUBLE_EQ(s.position_m(), 0.0123);
  EXPECT_DOUBLE_EQ(s.velocity_m_per_s(), -0.04);
  EXPECT_DOUBLE_EQ(s.force_n(), 1.5);
  EXPECT_DOUBLE_EQ(s.command_n(), -2.25);
  EXPECT_NEAR(s.fixture_penetration_m(), 0.0023, 1e-15);  // 0.0123 - 0.01, 1500 N/m in force
  EXPECT_DOUBLE_EQ(s.oscillation_amplitude_m(), 0.002);
  EXPECT_DOUBLE_EQ(s.oscillation_frequency_hz(), 7.5);
  EXPECT_TRUE(s.oscillating());
  EXPECT_DOUBLE_EQ(s.passivity_energy_j(), -0.25);

  // A message without cycles: the status follows it, the newest cycle stays.
  v1::Telemetry u;
  u.set_mode(v1::SAFE);
  u.set_mode_reason("peer silent");
  u.set_device("sim");
  u.set_sent_time_ns(10 * kS + 100 * kMs);
  u.mutable_loop()->set_overruns(9);
  b.add(u, 20 * kS + 100 * kMs);
  s = summary(b, 20 * kS + 100 * kMs);
  EXPECT_EQ(s.mode(), v1::SAFE);
  EXPECT_EQ(s.mode_reason(), "peer silent");
  EXPECT_EQ(s.loop().overruns(), 9U);
  EXPECT_EQ(s.link().accepted(), 0U);
  EXPECT_EQ(s.active().change_id(), 0U);  // this message carries no parameters
  EXPECT_EQ(s.active().master_fixture_stiffness_n_per_m(), 0.0);
  EXPECT_DOUBLE_EQ(s.position_m(), 0.0123);
  EXPECT_DOUBLE_EQ(s.command_n(), -2.25);
}

// ------------------------------------------------------------------------------------ monitors

struct PowerSample {
  double f;
  double v;
  v1::NodeMode mode;
};

TEST(FeedMonitors, PassivityIntegratesForceTimesVelocityWhileCoupled) {
  constexpr double kT = 0.001;
  const PowerSample samples[] = {
      {2.0, 0.5, v1::ENGAGED},
      {-1.0, 0.25, v1::ENGAGED},
      {4.0, -0.125, v1::CLUTCHED},  // clutched is still coupled
      {3.0, 1.0, v1::ENGAGED},
  };
  // By hand: T (2*0.5 - 1*0.25 - 4*0.125 + 3*1) = 0.001 * 3.25.
  const double hand = 0.001 * 3.25;
  for (const bool is_master : {true, false}) {
    OscillationMonitor osc(kT, 0.5, 1e-4);
    PassivityObserver obs(kT);
    std::int64_t t = 0;
    for (const PowerSample& p : samples) {
      feed_monitors(cycle(t += kMs, 0.0, p.v, p.f, 0.0, p.mode), is_master, osc, obs);
    }
    // The master's port force is the measured (human's) force; the slave's the opposite.
    const double expected = is_master ? hand : -hand;
    EXPECT_NEAR(read_monitors(osc, obs).passivity_energy_J, expected, 1e-15) << is_master;

    // Not coupled: the observer restarts...
    feed_monitors(cycle(t += kMs, 0.0, 1.0, 1.0, 0.0, v1::ARMED), is_master, osc, obs);
    EXPECT_EQ(read_monitors(osc, obs).passivity_energy_J, 0.0);
    // ... and counts from zero when coupled again: T * 2 * 2 = 0.004 (sign by side).
    feed_monitors(cycle(t += kMs, 0.0, 2.0, 2.0, 0.0, v1::ENGAGED), is_master, osc, obs);
    EXPECT_NEAR(read_monitors(osc, obs).passivity_energy_J, is_master ? 0.004 : -0.004, 1e-15);
  }
}

TEST(FeedMonitors, OscillationReadsZeroUntilFullThenTheSinesAmplitudeAndFrequency) {
  constexpr double kT = 0.001;  // period
  constexpr double kW = 0.5;    // window
  constexpr double kA = 1e-3;   // 1 mm
  constexpr double kF = 20.0;   // Hz
  OscillationMonitor osc(kT, kW, 1e-4);
  PassivityObserver obs(kT);
  auto x = [&](int k) { return kA * std::sin(2.0 * std::numbers::pi * kF * kT * k); };
  // Two windows (1000 samples) make the monitor full: one short of that it reads nothing,
  // although the signal oscillates.
  int k = 0;
  for (; k < 999; ++k) feed_monitors(cycle(k * kMs, x(k)), true, osc, obs);
  ASSERT_FALSE(osc.full());
  MonitorReadings r = read_monitors(osc, obs);
  EXPECT_EQ(r.oscillation_amplitude_m, 0.0);
  EXPECT_EQ(r.oscillation_frequency_hz, 0.0);
  EXPECT_FALSE(r.oscillating);

  for (; k < 1500; ++k) feed_monitors(cycle(k * kMs, x(k)), true, osc, obs);
  ASSERT_TRUE(osc.full());
  r = read_monitors(osc, obs);
  // Amplitude tolerance: the detector measures half the peak-to-peak about the window's
  // least-squares line. Over the window's 10 whole periods a sine has zero mean, but its
  // least-squares slope is up to 12 A / (w W^2) (w = 2 pi f), so the line departs from zero by
  // at most delta = 6 A / (w W) = 0.0955 mm at the window's ends, and moves each extreme by at
  // most delta. The samples (50 per period) come within pi/50 of phase of the peaks, a factor
  // cos(pi/50) = 0.998. So |amplitude - A| <= delta + A (1 - cos(pi/50)); 5 % margin for the
  // discrete sums.
  const double delta = 6.0 * kA / (2.0 * std::numbers::pi * kF * kW);
  const double amp_tol = 1.05 * (delta + kA * (1.0 - std::cos(std::numbers::pi / 50.0)));
  EXPECT_NEAR(r.oscillation_amplitude_m, kA, amp_tol);
  // Frequency tolerance: it counts the mean-line crossings in the window (2 per period, 20 in
  // 0.5 s); an end effect can add or lose one crossing, i.e. 1 / (2 * 0.5 s) = 1 Hz.
  EXPECT_NEAR(r.oscillation_frequency_hz, kF, 1.0 / (2.0 * kW));
  // 1 mm >= 0.1 mm, ~20 crossings >= 4, not decaying: a sustained oscillation.
  EXPECT_TRUE(r.oscillating);

  // Leaving the coupled modes empties it.
  feed_monitors(cycle(k * kMs, x(k), 0.0, 0.0, 0.0, v1::ARMED), true, osc, obs);
  EXPECT_FALSE(osc.full());
  r = read_monitors(osc, obs);
  EXPECT_EQ(r.oscillation_amplitude_m, 0.0);
  EXPECT_EQ(r.oscillation_frequency_hz, 0.0);
  EXPECT_FALSE(r.oscillating);
}

}  // namespace
}  // namespace teleop::supervisor

namespace teleop::supervisor {
namespace {

TEST(StatusBuilderAlignment, TheNewestCyclesAlignmentErrorReachesTheSummary) {
  // Aligning (issue 14, finding 11): the console shows the gap the operator is guided to close.
  NodeSummaryBuilder b(true, 0.01, 1000.0);
  std::vector<v1::CycleRecord> cycles;
  for (int k = 0; k < 5; ++k) {
    v1::CycleRecord c = cycle(kS + k * kMs, 0.02 - 0.001 * k, 0.0, 0.0, -0.5, v1::ALIGNING);
    c.set_alignment_error_m(0.016 - 0.001 * k);
    cycles.push_back(c);
  }
  send_in_batches(b, cycles, 2);
  EXPECT_EQ(summary(b, kS + 5 * kMs).alignment_error_m(), 0.016 - 0.001 * 4);
}

// ------------------------------------------------------------------------------- n > 1 axes

// The live summary of a three-axis node carries its newest cycle per axis (the console's norms
// and worst axes read them); tracking errors alpha x_m - x_s with alpha = 2, by hand:
// master (1, 2, 3) mm, peer slave (1.5, 4, 6.5) mm -> (0.5, 0, -0.5) mm.
TEST(StatusBuilderAxes, ThreeAxisCyclesFillEveryAxisAndTheTrackingErrors) {
  NodeSummaryBuilder master(true, 0.01, 1000.0, 5.0, 0.05, 2.0);
  NodeSummaryBuilder slave(false, 0.01, 1000.0, 5.0, 0.05, 2.0);
  const auto three = [](const std::vector<double>& own, const std::vector<double>& peer,
                        const std::vector<double>& force) {
    v1::CycleRecord c;
    c.set_sample_time_ns(kS);
    c.set_mode(v1::ENGAGED);
    c.set_axes(3);
    for (std::size_t i = 0; i < 3; ++i) {
      c.add_positions_m(own[i]);
      c.add_velocities_m_per_s(0.0);
      c.add_forces_n(force[i]);
      c.add_commands_n(-force[i]);
      c.add_peer_positions_m(peer[i]);
    }
    return c;
  };
  const std::vector<double> x_m{1e-3, 2e-3, 3e-3};
  const std::vector<double> x_s{1.5e-3, 4e-3, 6.5e-3};
  send_in_batches(master, {three(x_m, x_s, {0.5, -1.0, 2.0})}, 1);
  send_in_batches(slave, {three(x_s, x_m, {0.0, 0.0, -3.0})}, 1);
  const v1::NodeSummary m = summary(master, kS);
  ASSERT_EQ(m.axes(), 3U);
  ASSERT_EQ(m.positions_m_size(), 3);
  EXPECT_EQ(m.positions_m(2), 3e-3);
  EXPECT_EQ(m.forces_n(1), -1.0);
  EXPECT_EQ(m.commands_n(2), -2.0);
  ASSERT_EQ(m.tracking_errors_m_size(), 3);
  EXPECT_NEAR(m.tracking_errors_m(0), 0.5e-3, 1e-15);
  EXPECT_NEAR(m.tracking_errors_m(1), 0.0, 1e-15);
  EXPECT_NEAR(m.tracking_errors_m(2), -0.5e-3, 1e-15);
  // The slave's view: its own position is x_s, its peer's x_m; the same errors.
  const v1::NodeSummary s = summary(slave, kS);
  ASSERT_EQ(s.tracking_errors_m_size(), 3);
  EXPECT_NEAR(s.tracking_errors_m(2), -0.5e-3, 1e-15);
  EXPECT_EQ(s.forces_n(2), -3.0);
  // The traces are the norms: |x_m| = sqrt(1 + 4 + 9) mm, |F_m| = sqrt(0.25 + 1 + 4) N; the
  // penetration trace is the record's deepest plane (0 here: the cycle says none).
  ASSERT_GE(m.position_trace_m().max_size(), 1);
  EXPECT_NEAR(m.position_trace_m().max(m.position_trace_m().max_size() - 1), std::sqrt(14.0) * 1e-3,
              1e-9);
  EXPECT_NEAR(m.force_trace_n().max(m.force_trace_n().max_size() - 1), std::sqrt(5.25), 1e-6);
  // A one-axis node's summary keeps the lists empty.
  NodeSummaryBuilder one(true, 0.01, 1000.0);
  send_in_batches(one, {cycle(kS, 0.002)}, 1);
  const v1::NodeSummary o = summary(one, kS);
  EXPECT_EQ(o.axes(), 0U);
  EXPECT_EQ(o.positions_m_size(), 0);
  EXPECT_EQ(o.position_m(), 0.002);
}

}  // namespace
}  // namespace teleop::supervisor
