// The console's screen (issue 6) from hand-made summaries: every expected row, bar and plot
// cell below is worked out by hand from the layout rules stated in console_view.hpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <sstream>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "supervisor/teleopctl/console_view.hpp"

namespace teleop::ctl {
namespace {

bool has_line_starting(const std::vector<std::string>& lines, const std::string& prefix) {
  return std::any_of(lines.begin(), lines.end(),
                     [&](const std::string& l) { return l.rfind(prefix, 0) == 0; });
}

bool contains(const std::vector<std::string>& lines, const std::string& text) {
  return std::any_of(lines.begin(), lines.end(),
                     [&](const std::string& l) { return l.find(text) != std::string::npos; });
}

std::string joined(const std::vector<std::string>& lines) {
  std::string s;
  for (const std::string& l : lines) s += l + "\n";
  return s;
}

v1::SupervisorStatus engaged_status() {
  v1::SupervisorStatus s;
  s.set_time_ns(100'000'000'000);
  s.set_source("live");
  for (v1::NodeSummary* n : {s.mutable_master(), s.mutable_slave()}) {
    n->set_alive(true);
    n->set_mode(v1::ENGAGED);
    n->set_loop_rate_hz(1000.0);
    n->mutable_loop()->set_wakeup_p99_ns(45'000);
    n->mutable_loop()->set_overruns(12);
    n->set_overruns_last_minute(3);
    n->mutable_loop()->set_cycles(5000);
    n->mutable_rt()->set_fifo_priority(80);
    n->mutable_rt()->set_memory_locked(true);
    n->mutable_rt()->set_cpu(-1);
    n->mutable_link()->set_round_trip_ns(620'000);
    n->mutable_link()->set_round_trip_p99_ns(910'000);
    n->mutable_link()->set_round_trip_samples(1);
  }
  s.mutable_master()->set_position_m(0.01234);
  s.mutable_master()->set_force_n(1.5);
  v1::StabilityReport* r = s.mutable_report();
  r->set_verdict("stable");
  r->set_min_damping_ratio(0.0912);
  r->set_required_damping_ratio(0.05);
  r->set_round_trip_samples(1);
  r->set_sample_rate_hz(1000.0);
  r->set_slave_fixture_stiffness_n_per_m(1000.0);
  r->set_max_stable_slave_stiffness_n_per_m(4000.0);
  r->set_slave_margin(0.75);
  r->set_slave_crossing_above_n_per_m(4000.0);  // inside [0, limit] the limit is the next
  s.set_recording_file("/data/sessions/teleop-session-20261122-101500.mcap");
  s.set_recording_bytes(12'300'000);
  s.set_recorded_messages(4567);
  s.set_recording_drops(0);
  return s;
}

TEST(MarginBar, FillsInProportionToConfiguredOverMaximumWithTheLimitMarked) {
  // width 22: 20 inner cells, the last is the limit '|'; 1000/4000 of the 19 before it is
  // 4.75 -> 5 filled.
  EXPECT_EQ(margin_bar(1000.0, 4000.0, 22), "[#####..............|]");
  // At the limit: all 19 filled, then the limit mark.
  EXPECT_EQ(margin_bar(4000.0, 4000.0, 12), "[#########|]");
  // Zero stiffness: nothing filled.
  EXPECT_EQ(margin_bar(0.0, 4000.0, 7), "[....|]");
}

TEST(MarginBar, BeyondTheLimitTheBarIsFullAndEndsInABang) {
  EXPECT_EQ(margin_bar(5000.0, 4000.0, 12), "[#########!]");
  EXPECT_EQ(margin_bar(1.0, 0.0, 6), "[###!]");  // no stable stiffness at all
}

TEST(Plot, BandsArePlacedByValueNewestOnTheRight) {
  // Trace a: buckets [0,0], [1,1], [0,2] over a shared range [0, 2] on 3 rows:
  // row = (2 - v) / 2 * 2 -> v=2: row 0, v=1: row 1, v=0: row 2.
  v1::Trace a;
  for (const auto& [mn, mx] : {std::pair{0.f, 0.f}, std::pair{1.f, 1.f}, std::pair{0.f, 2.f}}) {
    a.add_min(mn);
    a.add_max(mx);
  }
  v1::Trace b;  // one bucket at 2: the newest column, row 0, where a's band also is -> '#'
  b.add_min(2.f);
  b.add_max(2.f);
  const std::vector<std::string> rows = render_plot(a, b, 3, 5, 1.0);
  ASSERT_EQ(rows.size(), 3u);
  // Columns 0, 1 empty (3 buckets right-aligned in 5 columns).
  EXPECT_EQ(rows[0], "    #");
  EXPECT_EQ(rows[1], "   mm");
  EXPECT_EQ(rows[2], "  m m");
}

TEST(Plot, OlderBucketsThanTheWidthScrollOffAndScaleApplies) {
  v1::Trace a;
  for (int i = 0; i < 10; ++i) {  // values 0..9 m; only the last 4 (6..9) are shown
    a.add_min(static_cast<float>(i));
    a.add_max(static_cast<float>(i));
  }
  const v1::Trace none;
  const std::vector<std::string> rows = render_plot(a, none, 4, 4, 1e3);
  // Range 6000..9000 (mm) on 4 rows: 9000 row 0, 8000 row 1, 7000 row 2, 6000 row 3.
  EXPECT_EQ(rows[0], "   m");
  EXPECT_EQ(rows[1], "  m ");
  EXPECT_EQ(rows[2], " m  ");
  EXPECT_EQ(rows[3], "m   ");
}

TEST(Plot, EmptyTracesGiveBlankRows) {
  const std::vector<std::string> rows = render_plot(v1::Trace{}, v1::Trace{}, 4, 10, 1.0);
  ASSERT_EQ(rows.size(), 4u);
  for (const std::string& r : rows) EXPECT_EQ(r, std::string(10, ' '));
}

TEST(ConsoleScreen, EightyByTwentyFourShowsNodesStabilityRecorderAndKeys) {
  ConsoleView v;
  v.status = engaged_status();
  v.source = "tcp://127.0.0.1:5566";
  const std::vector<std::string> lines = render_console(v, 24, 80);
  ASSERT_EQ(lines.size(), 24u) << joined(lines);
  for (const std::string& l : lines) EXPECT_LE(l.size(), 80u) << l;
  EXPECT_TRUE(has_line_starting(lines, "master ENGAGED")) << joined(lines);
  EXPECT_TRUE(has_line_starting(lines, "slave  ENGAGED")) << joined(lines);
  EXPECT_TRUE(contains(lines, "1000.0")) << joined(lines);  // loop rate
  EXPECT_TRUE(contains(lines, "45us")) << joined(lines);    // wake-up p99
  EXPECT_TRUE(contains(lines, "12/3")) << joined(lines);    // overruns total / last minute
  EXPECT_TRUE(contains(lines, "FIFO80 lock")) << joined(lines);
  EXPECT_TRUE(contains(lines, "x+12.34mm")) << joined(lines);
  EXPECT_TRUE(contains(lines, "rtt 0.62 p99 0.91 ms 1 smp")) << joined(lines);
  EXPECT_TRUE(contains(lines, "stability STABLE  zeta min 0.0912 (required 0.0500)"))
      << joined(lines);
  EXPECT_TRUE(has_line_starting(lines, "slave  fixture   1000 of   4000 N/m [")) << joined(lines);
  EXPECT_TRUE(contains(lines, "margin   75%")) << joined(lines);
  // The nearest crossings: none below, the limit 3000 N/m above (issue 15).
  EXPECT_TRUE(contains(lines, "margin   75% x-/+3000")) << joined(lines);
  EXPECT_TRUE(has_line_starting(lines, "master fixture none")) << joined(lines);
  EXPECT_TRUE(contains(lines, "teleop-session-20261122-101500.mcap  12.3 MB  4567 msgs  0 drops"))
      << joined(lines);
  EXPECT_EQ(lines.back().rfind("x E-STOP", 0), 0u) << lines.back();
  EXPECT_EQ(lines.front().find("NO SUMMARY"), std::string::npos);
}

// docs/nodes.md "Before engage": an experiment flag that arms what the analysis refuses, and
// nodes whose configurations differ, are said right under the header, whatever else is shown.
TEST(ConsoleScreen, TheExperimentBannerAndAConfigurationMismatchAreRightUnderTheHeader) {
  ConsoleView v;
  v.status = engaged_status();
  EXPECT_FALSE(contains(render_console(v, 24, 80), "EXPERIMENT"));
  v.status->set_experiment_banner(
      "EXPERIMENT: experiment.allow_unstable is set on the master and slave: configurations "
      "predicted unstable may engage");
  v.status->set_configuration_mismatch(
      "configuration fingerprints differ: supervisor 00000000000000aa, slave 00000000000000bb");
  const std::vector<std::string> lines = render_console(v, 24, 80);
  ASSERT_EQ(lines.size(), 24u) << joined(lines);
  for (const std::string& l : lines) EXPECT_LE(l.size(), 80u) << l;
  EXPECT_EQ(lines[1].rfind("!! EXPERIMENT: experiment.allow_unstable is set", 0), 0u)
      << joined(lines);
  EXPECT_EQ(lines[2].rfind("!! CONFIGURATION MISMATCH: configuration fingerprints differ", 0), 0u)
      << joined(lines);
  // The rest of the screen is still there.
  EXPECT_TRUE(has_line_starting(lines, "master ENGAGED")) << joined(lines);
  EXPECT_TRUE(contains(lines, "stability STABLE")) << joined(lines);
  EXPECT_EQ(lines.back().rfind("x E-STOP", 0), 0u) << lines.back();
}

TEST(ConsoleScreen, ARecorderStoppedByAnErrorSaysSo) {
  ConsoleView v;
  v.status = engaged_status();
  v.status->set_recording_error("write failed: No space left on device");
  EXPECT_TRUE(contains(render_console(v, 24, 80),
                       "recorder  STOPPED: teleop-session-20261122-101500.mcap"));
}

TEST(ConsoleScreen, AStaleOrMissingSummaryIsSaidInTheHeader) {
  ConsoleView v;
  v.status = engaged_status();
  v.status_age_ns = 2'500'000'000;
  EXPECT_NE(render_console(v, 24, 80).front().find("NO SUMMARY FOR 2.5 s"), std::string::npos);
  v.status.reset();
  EXPECT_NE(render_console(v, 24, 80).front().find("WAITING FOR THE SUMMARY"), std::string::npos);
}

TEST(ConsoleScreen, SilentAndSafeNodesShowTheirReason) {
  ConsoleView v;
  v.status = engaged_status();
  v.status->mutable_master()->set_mode(v1::SAFE);
  v.status->mutable_master()->set_mode_reason("peer silent for 30 ms");
  v.status->mutable_slave()->set_alive(false);
  v.status->mutable_slave()->set_mode_reason("e-stop");
  const std::vector<std::string> lines = render_console(v, 24, 80);
  EXPECT_TRUE(has_line_starting(lines, "master SAFE")) << joined(lines);
  EXPECT_TRUE(contains(lines, "peer silent for 30 ms")) << joined(lines);
  EXPECT_TRUE(has_line_starting(lines, "slave  SILENT")) << joined(lines);
}

TEST(ConsoleScreen, AnAligningNodeShowsItsAlignmentErrorInMillimetres) {
  // Aligning after a safe (issue 14, finding 11): the operator is guided to close the gap
  // alpha x_m - x_s, so the row shows it (here 21.40 mm - 4.10 mm = +17.30 mm) next to x.
  ConsoleView v;
  v.status = engaged_status();
  for (v1::NodeSummary* n : {v.status->mutable_master(), v.status->mutable_slave()}) {
    n->set_mode(v1::ALIGNING);
    n->set_alignment_error_m(0.0173);
  }
  v.status->mutable_master()->set_position_m(0.0214);
  v.status->mutable_slave()->set_position_m(0.0041);
  const std::vector<std::string> lines = render_console(v, 24, 80);
  for (const std::string& l : lines) EXPECT_LE(l.size(), 80u) << l;
  EXPECT_TRUE(has_line_starting(lines, "master ALIGNING")) << joined(lines);
  EXPECT_TRUE(contains(lines, "x+21.40mm gap+17.30mm")) << joined(lines);
  EXPECT_TRUE(contains(lines, "x +4.10mm gap+17.30mm")) << joined(lines);
  // Engaged, the row shows the force instead (the gap is the coupling's business then).
  v.status->mutable_master()->set_mode(v1::ENGAGED);
  v.status->mutable_slave()->set_mode(v1::ENGAGED);
  EXPECT_FALSE(contains(render_console(v, 24, 80), "gap+17.30mm"));
}

TEST(ConsoleScreen, AlarmsNewestFirstWithTheirAgeEvidenceAndAction) {
  ConsoleView v;
  v.status = engaged_status();
  v1::Alarm* a = v.status->add_recent_alarms();
  a->set_time_ns(98'000'000'000);  // 2 s before the status
  a->set_severity(v1::Alarm::ACTION);
  a->set_kind("oscillation");
  a->set_side("slave");
  a->set_message("sustained");
  v1::Evidence* e = a->add_evidence();
  e->set_name("amplitude");
  e->set_value(2.6);
  e->set_unit("mm");
  a->set_action("lowered");
  v1::Alarm* b = v.status->add_recent_alarms();
  b->set_time_ns(90'000'000'000);
  b->set_severity(v1::Alarm::WARNING);
  b->set_kind("loss");
  b->set_side("master");
  b->set_message("lost");
  const std::vector<std::string> lines = render_console(v, 24, 80);
  const auto first = std::find_if(lines.begin(), lines.end(), [](const std::string& l) {
    return l.find("ACTN oscillation slave: sustained amplitude=2.6mm -> lowered") !=
           std::string::npos;
  });
  const auto second = std::find_if(lines.begin(), lines.end(), [](const std::string& l) {
    return l.find("WARN loss master: lost") != std::string::npos;
  });
  ASSERT_NE(first, lines.end()) << joined(lines);
  ASSERT_NE(second, lines.end()) << joined(lines);
  EXPECT_LT(first, second);
  EXPECT_NE(first->find("-2.0s"), std::string::npos) << *first;
  EXPECT_NE(second->find("-10.0s"), std::string::npos) << *second;
}

TEST(ConsoleScreen, ALongMessageWrapsAtWordsSoItsEndIsOnScreen) {
  ConsoleView v;
  v.status = engaged_status();
  const std::string reason =
      "REFUSED by the supervisor: the analyser predicts an unstable teleoperator (minimum "
      "damping ratio -0.0324, round trip 1 samples)";
  v.messages = {"older", reason};
  const std::vector<std::string> lines = render_console(v, 24, 80);
  // 123 characters: the last space within 80 columns is the one after "teleoperator" (73), so
  // rows 21 and 22 hold it at that word; row 20 the older message.
  EXPECT_EQ(lines[20], "older");
  EXPECT_EQ(lines[21], "REFUSED by the supervisor: the analyser predicts an unstable teleoperator");
  EXPECT_EQ(lines[22], "(minimum damping ratio -0.0324, round trip 1 samples)");
}

TEST(ConsoleScreen, APredictionAndItsVerdictAreBothWholeWhenTheAlarmsLeaveRoom) {
  // What the set key shows for a change predicted unstable: two messages of two rows each.
  // With no alarm the 24 rows leave 7 free (24 - 16 fixed - the key line), so the message area
  // grows from 3 to 4 rows and the prediction's first row stays on screen.
  ConsoleView v;
  v.status = engaged_status();
  v.messages = {
      "prediction for slave.fixture.stiffness_N_per_m=9000: unstable, zeta min -0.0720 "
      "(required 0.0000), slave max 4344 N/m",
      "REFUSED by the supervisor: the analyser predicts an unstable teleoperator (minimum "
      "damping ratio -0.0720, round trip 1 samples)"};
  const std::vector<std::string> lines = render_console(v, 24, 80);
  ASSERT_EQ(lines.size(), 24u);
  EXPECT_EQ(lines[19],
            "prediction for slave.fixture.stiffness_N_per_m=9000: unstable, zeta min -0.0720");
  EXPECT_EQ(lines[20], "(required 0.0000), slave max 4344 N/m");
  EXPECT_EQ(lines[21], "REFUSED by the supervisor: the analyser predicts an unstable teleoperator");
  EXPECT_EQ(lines[22], "(minimum damping ratio -0.0720, round trip 1 samples)");
  EXPECT_EQ(lines[23].rfind("x E-STOP", 0), 0u);
}

v1::Alarm* add_alarm(v1::SupervisorStatus& s, std::int64_t time_ns, const std::string& message,
                     const std::string& kind = "oscillation") {
  v1::Alarm* a = s.add_recent_alarms();
  a->set_time_ns(time_ns);
  a->set_severity(v1::Alarm::WARNING);
  a->set_kind(kind);
  a->set_side("slave");
  a->set_message(message);
  return a;
}

TEST(ConsoleScreen, AnAlarmsEvidenceWrapsOntoASecondRowWhileTheRowsAllowIt) {
  ConsoleView v;
  v.status = engaged_status();
  v1::Alarm* a = add_alarm(*v.status, 98'000'000'000, "sustained oscillation");
  for (const auto& [name, value, unit] :
       {std::tuple{"amplitude", 0.541, "mm"}, std::tuple{"frequency", 16.0, "Hz"},
        std::tuple{"previous_amplitude", 0.143, "mm"}}) {
    v1::Evidence* e = a->add_evidence();
    e->set_name(name);
    e->set_value(value);
    e->set_unit(unit);
  }
  // "   -2.0s WARN oscillation slave: sustained oscillation amplitude=0.541mm frequency=16Hz
  // previous_amplitude=0.143mm" is 114 characters; the last space within 80 columns is the
  // one at 72, before "frequency": the rest goes on a second row under the message (9
  // columns in).
  std::vector<std::string> lines = render_console(v, 24, 80);
  EXPECT_EQ(lines[16], "   -2.0s WARN oscillation slave: sustained oscillation amplitude=0.541mm");
  EXPECT_EQ(lines[17], "         frequency=16Hz previous_amplitude=0.143mm");

  // Seven alarms (of different kinds: repeats of one kind would be grouped): the message area
  // keeps its 3 rows, which leaves 7 - 3 = 4 rows, so the newest four alarms get one row each,
  // newest first.
  const char* kinds[] = {"heartbeat", "round_trip", "loss", "overruns", "passivity", "node_state"};
  for (int i = 1; i <= 6; ++i)
    add_alarm(*v.status, 90'000'000'000 - i, "older " + std::to_string(i), kinds[i - 1]);
  v.messages = {"a message"};
  lines = render_console(v, 24, 80);
  ASSERT_EQ(lines.size(), 24u);
  EXPECT_EQ(lines[16].rfind("   -2.0s WARN oscillation slave: sustained oscillation amplitude=", 0),
            0u)
      << joined(lines);
  EXPECT_NE(lines[17].find("older 1"), std::string::npos) << joined(lines);
  EXPECT_NE(lines[19].find("older 3"), std::string::npos) << joined(lines);
  EXPECT_EQ(lines[22], "a message");

  // Its evidence, cut from that one row, comes in turn in the same row: the text wrapped 6
  // columns narrower (the same break, at 72), a page of one row each 3 s of the wall clock, the
  // page's number at the end of the row (" [p/N]" in the last 6 columns).
  const std::string first =
      "   -2.0s WARN oscillation slave: sustained oscillation amplitude=0.541mm";
  const std::string second = "         frequency=16Hz previous_amplitude=0.143mm";
  for (const auto& [clock_s, row] : {std::pair{0.0, first + "   [1/2]"},
                                     std::pair{4.0, second + std::string(24, ' ') + " [2/2]"},
                                     std::pair{6.5, first + "   [1/2]"}}) {
    v.clock_s = clock_s;
    lines = render_console(v, 24, 80);
    ASSERT_EQ(lines.size(), 24u);
    EXPECT_EQ(lines[16], row) << clock_s << "\n" << joined(lines);
    // The others stay where they were.
    EXPECT_NE(lines[17].find("older 1"), std::string::npos) << joined(lines);
    EXPECT_NE(lines[19].find("older 3"), std::string::npos) << joined(lines);
    EXPECT_EQ(lines[22], "a message");
  }
  v.clock_s = -1.0;

  // Two alarms in the same room: the first takes its two rows, the second one.
  v.status->mutable_recent_alarms()->DeleteSubrange(2, 5);
  lines = render_console(v, 24, 80);
  EXPECT_EQ(lines[17], "         frequency=16Hz previous_amplitude=0.143mm") << joined(lines);
  EXPECT_NE(lines[18].find("older 1"), std::string::npos) << joined(lines);
}

TEST(ConsoleScreen, ALongAlarmTakesTheRowsItNeedsAndPagesThroughTheRestAt80x24) {
  ConsoleView v;
  v.status = engaged_status();
  // 4 alarm rows at 80x24 (ATallerTerminalGivesThePlotsAndTheAlarmsTheExtraRows). An alarm
  // of 5 rows at 80 columns, and an older one: the newest takes 4 - 1 = 3 rows, pages of 3.
  std::string words;
  for (int i = 0; i < 40; ++i) words += " word" + std::to_string(i);
  add_alarm(*v.status, 98'000'000'000, "long:" + words);
  add_alarm(*v.status, 90'000'000'000, "older", "loss");
  // The row "   -2.0s WARN oscillation slave: long: word0 ... word39" is 308 characters:
  // word-wrapped at 80 columns (continuations indented 9) 5 rows, so it pages; at 74 (80 less
  // the mark) 5 rows too ("word5", "word15", "word24", "word33" end the first four): two
  // pages of 3 rows, the second's last row blank.
  std::vector<std::string> all;
  for (int turn = 0; turn < 4; ++turn) {
    v.clock_s = 3.0 * turn + 0.5;  // a page each 3 s: 1, 2, 1, 2
    const std::vector<std::string> lines = render_console(v, 24, 80);
    ASSERT_EQ(lines.size(), 24u);
    for (const std::string& l : lines) EXPECT_LE(l.size(), 80u) << l;
    const int page = turn % 2 + 1;
    ASSERT_EQ(lines[16].size(), 80u) << joined(lines);
    EXPECT_EQ(lines[16].substr(74), " [" + std::to_string(page) + "/2]") << joined(lines);
    if (page == 1) {
      EXPECT_EQ(lines[16].substr(0, 74),
                "   -2.0s WARN oscillation slave: long: word0 word1 word2 word3 word4 word5");
      EXPECT_EQ(lines[18].rfind("         word16 ", 0), 0U) << lines[18];
    } else {
      EXPECT_EQ(lines[16].rfind("         word25 ", 0), 0U) << lines[16];
      EXPECT_EQ(lines[17], "         word34 word35 word36 word37 word38 word39");
      EXPECT_EQ(lines[18], "");
    }
    if (turn < 2) {
      all.push_back(lines[16].substr(0, 74));
      all.push_back(lines[17]);
      all.push_back(lines[18]);
    }
    // The older alarm keeps its row under it.
    EXPECT_EQ(lines[19], "  -10.0s WARN loss slave: older") << joined(lines);
  }
  // Both pages together: every word of the alarm once, in order.
  std::vector<std::string> shown;
  for (const std::string& r : all) {
    std::istringstream in(r);
    for (std::string w; in >> w;) shown.push_back(w);
  }
  std::vector<std::string> expected = {"-2.0s", "WARN", "oscillation", "slave:", "long:"};
  for (int i = 0; i < 40; ++i) expected.push_back("word" + std::to_string(i));
  EXPECT_EQ(shown, expected);
}

TEST(ConsoleScreen, ReadOnlyReplayAndHelpScreens) {
  ConsoleView v;
  v.status = engaged_status();
  v.read_only = true;
  std::vector<std::string> lines = render_console(v, 24, 80);
  EXPECT_NE(lines.front().find("[read-only]"), std::string::npos);
  EXPECT_EQ(lines.back(), "READ-ONLY  x E-STOP  ? help  q quit");

  // Typing a change: the key line says how to send, cancel and e-stop.
  v.read_only = false;
  v.prompt = "set (PATH=VALUE ...)> gains.kp_";
  lines = render_console(v, 24, 80);
  EXPECT_EQ(lines.back(), "typing: Enter sends  Esc cancels  Ctrl-X E-STOP");
  EXPECT_EQ(lines[22], "set (PATH=VALUE ...)> gains.kp_");
  v.prompt.clear();

  v.replay = true;
  v1::ReplayPosition* r = v.status->mutable_replay();
  r->set_file("/tmp/x/session.mcap");
  r->set_state("paused");
  r->set_position_s(12.25);
  r->set_duration_s(60.0);
  r->set_speed(2.0);
  lines = render_console(v, 24, 80);
  EXPECT_EQ(lines.front().rfind("TELEOP REPLAY  paused 12.2/60.0 s  x2  session.mcap", 0), 0u)
      << lines.front();
  EXPECT_EQ(lines.back().rfind("space pause/resume", 0), 0u);

  v.help = true;
  lines = render_console(v, 24, 80);
  EXPECT_TRUE(contains(lines, "pause / resume")) << joined(lines);
  v.replay = false;
  lines = render_console(v, 24, 80);
  EXPECT_TRUE(contains(lines, "E-STOP both nodes")) << joined(lines);
  ASSERT_EQ(lines.size(), 24u);
}

TEST(ConsoleScreen, HelpAndKeyLinesFitEightyColumnsUncut) {
  // Rendered 200 wide nothing is cut: every help and key line must still be at most 80.
  ConsoleView v;
  v.status = engaged_status();
  v.help = true;
  for (const bool replay : {false, true}) {
    for (const bool read_only : {false, true}) {
      v.replay = replay;
      v.read_only = read_only;
      const std::vector<std::string> lines = render_console(v, 24, 200);
      for (std::size_t i = 1; i < lines.size(); ++i) EXPECT_LE(lines[i].size(), 80u) << lines[i];
    }
  }
}

TEST(ConsoleScreen, ASmallTerminalGetsAsManyRowsAsItHasKeysLast) {
  ConsoleView v;
  v.status = engaged_status();
  const std::vector<std::string> lines = render_console(v, 10, 40);
  ASSERT_EQ(lines.size(), 10u);
  for (const std::string& l : lines) EXPECT_LE(l.size(), 40u);
  EXPECT_EQ(lines.back().rfind("x E-STOP", 0), 0u);
  EXPECT_TRUE(has_line_starting(lines, "master ENGAGED")) << joined(lines);
}

// Issue 17: a node in fault or safe is said in a banner under the header, its reason whole
// (word-wrapped, continuation rows indented 3), and the node row points to it when the reason
// does not fit the row.
TEST(ConsoleScreen, SafeAndFaultBannersCarryTheWholeReasonAt80x24) {
  ConsoleView v;
  v.status = engaged_status();
  const std::string reason =
      "encoder jump of 812 counts in one cycle (limit 64): the position reading is not "
      "trusted; check the encoder cable and its supply, then clear";
  v.status->mutable_master()->set_mode(v1::FAULT);
  v.status->mutable_master()->set_mode_reason(reason);
  v.status->mutable_slave()->set_mode(v1::SAFE);
  v.status->mutable_slave()->set_mode_reason("peer silent for 30 ms");
  const std::vector<std::string> lines = render_console(v, 24, 80);
  ASSERT_EQ(lines.size(), 24u) << joined(lines);
  for (const std::string& l : lines) EXPECT_LE(l.size(), 80u) << l;
  // "!! FAULT MASTER: " + reason is 156 characters: the last space within 80 is after "the"
  // (72); the next row's 77 columns end exactly at "then" (3 + 77 = 80); "clear" is left.
  EXPECT_EQ(lines[1], "!! FAULT MASTER: encoder jump of 812 counts in one cycle (limit 64): the");
  EXPECT_EQ(lines[2],
            "   position reading is not trusted; check the encoder cable and its supply, then");
  EXPECT_EQ(lines[3], "   clear");
  EXPECT_EQ(lines[4], "!! SAFE SLAVE: peer silent for 30 ms");
  // The node rows: 57 columns before the reason; the master's 156 do not fit (a pointer to the
  // banner), the slave's 1 + 21 do (79).
  EXPECT_EQ(lines[6].rfind("master FAULT", 0), 0u) << lines[6];
  EXPECT_EQ(lines[6].substr(57), " (reason above)");
  EXPECT_EQ(lines[7].rfind("slave  SAFE", 0), 0u) << lines[7];
  EXPECT_EQ(lines[7].substr(57), " peer silent for 30 ms");
  EXPECT_TRUE(has_line_starting(lines, "stability STABLE")) << joined(lines);
  EXPECT_EQ(lines.back().rfind("x E-STOP", 0), 0u);

  // Both stopped for one reason: one banner.
  v.status->mutable_master()->set_mode(v1::SAFE);
  v.status->mutable_master()->set_mode_reason("e-stop");
  v.status->mutable_slave()->set_mode_reason("e-stop");
  const std::vector<std::string> both = render_console(v, 24, 80);
  EXPECT_EQ(both[1], "!! SAFE MASTER AND SLAVE: e-stop");
  EXPECT_EQ(both[2].rfind("node ", 0), 0u) << joined(both);
  // Engaged: no banner.
  v.status->mutable_master()->set_mode(v1::ENGAGED);
  v.status->mutable_slave()->set_mode(v1::ENGAGED);
  EXPECT_FALSE(contains(render_console(v, 24, 80), "!! ")) << joined(render_console(v, 24, 80));
}

TEST(ConsoleScreen, ASilentNodesLongReasonContinuesOnDetailRows) {
  // Not safe or fault (no banner): the reason goes on rows of its own under the state column
  // (7 in), wrapped to 73 columns.
  ConsoleView v;
  v.status = engaged_status();
  v.status->mutable_slave()->set_alive(false);
  v.status->mutable_slave()->set_mode_reason(
      "no telemetry from tcp://10.0.0.2:5565 for 2.0 s (the node stopped, or a firewall drops "
      "the port)");
  const std::vector<std::string> lines = render_console(v, 24, 80);
  EXPECT_EQ(lines[3].rfind("slave  SILENT", 0), 0u) << joined(lines);
  EXPECT_EQ(lines[3].size(), 57u) << lines[3];
  EXPECT_EQ(lines[4],
            "       no telemetry from tcp://10.0.0.2:5565 for 2.0 s (the node stopped, or a");
  EXPECT_EQ(lines[5], "       firewall drops the port)");
  EXPECT_EQ(lines[6].rfind("link ", 0), 0u);
}

// ACTION alarms (never grouped) m1 (1 s old) .. mN, newest first.
std::vector<v1::Alarm> distinct_alarms(std::int64_t now_ns, int n) {
  std::vector<v1::Alarm> out;
  for (int i = 1; i <= n; ++i) {
    v1::Alarm a;
    a.set_time_ns(now_ns - i * 1'000'000'000LL);
    a.set_severity(v1::Alarm::ACTION);
    a.set_kind("oscillation");
    a.set_side("slave");
    a.set_message("m" + std::to_string(i));
    out.push_back(a);
  }
  return out;
}

TEST(ConsoleScreen, ATallerTerminalGivesThePlotsAndTheAlarmsTheExtraRows) {
  ConsoleView v;
  v.status = engaged_status();
  v.alarm_history = distinct_alarms(v.status->time_ns(), 30);
  // 80x24: 16 rows before the alarms (header 1, table 3, link 1, titles 1 + plot 4,
  // stability 3, monitors, recorder, count), the key line, 3 message rows: 4 alarm rows.
  std::vector<std::string> lines = render_console(v, 24, 80);
  ASSERT_EQ(lines.size(), 24u);
  EXPECT_EQ(lines[10].rfind("stability STABLE", 0), 0u) << joined(lines);
  EXPECT_EQ(lines[15], "alarms (newest first): 30");
  EXPECT_EQ(lines[16], "   -1.0s ACTN oscillation slave: m1");
  EXPECT_EQ(lines[19], "   -4.0s ACTN oscillation slave: m4");
  EXPECT_EQ(lines[20], "");
  EXPECT_EQ(
      std::count_if(lines.begin(), lines.end(),
                    [](const std::string& l) { return l.find(" ACTN ") != std::string::npos; }),
      4);
  // 100x40: 16 rows more; the plots take 4 of them ((40 - 24) / 4, to 8 rows), the alarms
  // the other 12: 20 rows before the alarms, 40 - 20 - 1 - 3 = 16 alarm rows.
  lines = render_console(v, 40, 100);
  ASSERT_EQ(lines.size(), 40u);
  for (const std::string& l : lines) EXPECT_LE(l.size(), 100u) << l;
  EXPECT_EQ(lines[5].rfind("x mm", 0), 0u) << joined(lines);
  EXPECT_EQ(lines[14].rfind("stability STABLE", 0), 0u) << joined(lines);
  EXPECT_EQ(lines[19], "alarms (newest first): 30");
  EXPECT_EQ(lines[20], "   -1.0s ACTN oscillation slave: m1");
  EXPECT_EQ(lines[35], "  -16.0s ACTN oscillation slave: m16");
  EXPECT_EQ(lines[36], "");
  EXPECT_EQ(lines[39].rfind("x E-STOP", 0), 0u);
  // The plots' panels are (100 - 2) / 3 = 32 wide.
  EXPECT_EQ(lines[6].size(), 32u * 3 + 2);
}

TEST(ConsoleScreen, FiftyRepeatedWarningsTakeOneEntryWithTheCountAndTheLastTime) {
  ConsoleView v;
  v.status = engaged_status();  // time 100 s
  v.clock = "12:03:06";
  v.clock_s = 12 * 3600 + 3 * 60 + 6.25;  // 12:03:06.25
  const std::int64_t now = v.status->time_ns();
  auto warning = [](std::int64_t t, const char* kind, const char* side, const char* message) {
    v1::Alarm a;
    a.set_time_ns(t);
    a.set_severity(v1::Alarm::WARNING);
    a.set_kind(kind);
    a.set_side(side);
    a.set_message(message);
    return a;
  };
  // 50 overrun warnings once a second, 2 s to 51 s old; an action 10.5 s old and a loss
  // warning 20.5 s old among them; newest first.
  for (int k = 0; k < 50; ++k) {
    const std::int64_t t = now - 2'000'000'000LL - k * 1'000'000'000LL;
    if (k == 9) {
      v1::Alarm act;
      act.set_time_ns(now - 10'500'000'000LL);
      act.set_severity(v1::Alarm::ACTION);
      act.set_kind("oscillation");
      act.set_side("slave");
      act.set_message("sustained");
      act.set_action("lowered");
      v.alarm_history.push_back(act);
    }
    if (k == 19) {
      v.alarm_history.push_back(
          warning(now - 20'500'000'000LL, "loss", "master", "more than 1 % of peer states lost"));
    }
    v1::Alarm a = warning(t, "overruns", "slave", "loop overran in the last second");
    v1::Evidence* e = a.add_evidence();
    e->set_name("overruns");
    e->set_value(3);
    v.alarm_history.push_back(a);
  }
  ASSERT_EQ(v.alarm_history.size(), 52u);
  const std::vector<std::string> lines = render_console(v, 24, 80);
  ASSERT_EQ(lines.size(), 24u) << joined(lines);
  EXPECT_EQ(lines[15], "alarms (newest first): 52, shown as 3 with repeated warnings grouped");
  // The newest overrun 2 s before 12:03:06; the first 49 s before it. 98 characters: the
  // last space within 80 is the one after "last" (80), the rest 9 in. Three entries in four
  // rows: the first gets two.
  EXPECT_EQ(lines[16],
            "   -2.0s WARN overruns slave x50 in 49s, last 12:03:04: loop overran in the last");
  EXPECT_EQ(lines[17], "         second overruns=3");
  EXPECT_EQ(lines[18], "  -10.5s ACTN oscillation slave: sustained -> lowered");
  EXPECT_EQ(lines[19], "  -20.5s WARN loss master: more than 1 % of peer states lost");
  // A summary 0.5 s old at 12:03:06.25: the newest was 2.5 s ago, at 12:03:03.75.
  v.status_age_ns = 500'000'000;
  EXPECT_TRUE(contains(render_console(v, 24, 80), "x50 in 49s, last 12:03:03: loop"))
      << joined(render_console(v, 24, 80));
  v.status_age_ns = 0;
  // Replayed, the wall clock says nothing about the alarm: the count and span only.
  v.replay = true;
  EXPECT_TRUE(contains(render_console(v, 24, 80), "   -2.0s WARN overruns slave x50 in 49s: loop"))
      << joined(render_console(v, 24, 80));
}

TEST(ConsoleScreen, WithoutAHistoryTheSummarysOwnAlarmsAreGrouped) {
  ConsoleView v;
  v.status = engaged_status();
  for (int k = 0; k < 20; ++k) {
    add_alarm(*v.status, v.status->time_ns() - (k + 1) * 1'000'000'000LL, "lost", "loss");
  }
  const std::vector<std::string> lines = render_console(v, 24, 80);
  EXPECT_EQ(lines[15], "alarms (newest first): 20, shown as 1 with repeated warnings grouped");
  EXPECT_EQ(lines[16], "   -1.0s WARN loss slave x20 in 19s: lost");
  // Another message of the same kind and side (another condition, e.g. two different
  // commands) is an entry of its own.
  v.status->mutable_recent_alarms(5)->set_message("lost again");
  const std::vector<std::string> two = render_console(v, 24, 80);
  EXPECT_EQ(two[15], "alarms (newest first): 20, shown as 2 with repeated warnings grouped");
  EXPECT_EQ(two[16], "   -1.0s WARN loss slave x19 in 19s: lost");
  EXPECT_EQ(two[17], "   -6.0s WARN loss slave: lost again");
}

TEST(AlarmHistory, KeepsEveryAlarmOnceAcrossSummariesOfTheNewestTwenty) {
  // 100 alarms, one a second; a summary every 5 s carries the newest 20 so far (as the
  // supervisor's status does): the history ends with all 100, newest first, each once.
  AlarmHistory h;
  for (int t = 5; t <= 100; t += 5) {
    v1::SupervisorStatus s;
    s.set_time_ns(t * 1'000'000'000LL);
    for (int i = t; i >= std::max(1, t - 19); --i) {
      add_alarm(s, i * 1'000'000'000LL, "a" + std::to_string(i), "overruns");
    }
    h.merge(s);
    h.merge(s);  // the same summary twice adds nothing
  }
  ASSERT_EQ(h.newest_first().size(), 100u);
  for (int i = 0; i < 100; ++i) {
    EXPECT_EQ(h.newest_first()[static_cast<std::size_t>(i)].message(),
              "a" + std::to_string(100 - i));
  }
  // Two alarms at the same instant are two alarms.
  v1::SupervisorStatus s;
  s.set_time_ns(101'000'000'000LL);
  add_alarm(s, 101'000'000'000LL, "x", "loss");
  add_alarm(s, 101'000'000'000LL, "y", "loss");
  h.merge(s);
  EXPECT_EQ(h.newest_first().size(), 102u);
  // A replay seeked back (the summary's clock went back): the history starts over.
  v1::SupervisorStatus back;
  back.set_time_ns(30'000'000'000LL);
  add_alarm(back, 29'000'000'000LL, "a29", "overruns");
  h.merge(back);
  ASSERT_EQ(h.newest_first().size(), 1u);
  EXPECT_EQ(h.newest_first()[0].message(), "a29");
}

TEST(AlarmHistory, HoldsAtMostItsCapacityDroppingTheOldest) {
  AlarmHistory h(10);
  v1::SupervisorStatus s;
  s.set_time_ns(50'000'000'000LL);
  for (int i = 20; i >= 1; --i) add_alarm(s, i * 1'000'000'000LL, "a" + std::to_string(i));
  h.merge(s);
  ASSERT_EQ(h.newest_first().size(), 10u);
  EXPECT_EQ(h.newest_first().front().message(), "a20");
  EXPECT_EQ(h.newest_first().back().message(), "a11");
}

}  // namespace
}  // namespace teleop::ctl
