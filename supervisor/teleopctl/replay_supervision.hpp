// What `teleopctl replay` asks of the supervisor's logic (supervisor/core, never the daemon):
// the summary stream a replay publishes, built from the recorded telemetry by the monitors and
// node summaries the supervisor feeds from live telemetry, and the guard's analysis of a set
// of parameters.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <iosfwd>
#include <nlohmann/json.hpp>
#include <optional>
#include <string_view>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/core/teleop_params.hpp"
#include "common/session/session_reader.hpp"
#include "supervisor/core/monitors.hpp"
#include "supervisor/core/status_builder.hpp"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::ctl {

// How the summary stream's monitors and node summaries are set up: as teleop-supervisor sets
// up its own from the same configuration (supervisor_app.cpp).
struct SummarySetup {
  double period_s{1e-3};
  double oscillation_threshold_m{0.0};
  FixtureParams master_fixture{};
  FixtureParams slave_fixture{};
};

// From the recorded configuration (with any --set applied); defaults without one, or when it
// does not describe the teleoperator (then saying so on `err`).
[[nodiscard]] SummarySetup summary_setup(const std::optional<config::LoadedConfig>& cfg,
                                         std::ostream& err);

// What the summary stream shows at a position of the replay: the file's messages up to that
// log time, fed as teleop-supervisor feeds what it receives (fill_status in supervisor_app.cpp),
// with the recorded log times for its clock.
class ReplaySummary {
 public:
  enum Kind { kMaster = 0, kSlave = 1, kReport = 2, kAlarm = 3, kRecordedStatus = 4 };
  struct Item {
    Kind kind{kMaster};
    std::uint64_t log_time_ns{0};
    std::string_view data{};  // valid while the session file is open
  };

  ReplaySummary(const SummarySetup& setup, std::vector<Item> items)
      : items_(std::move(items)),
        master_(true, setup.master_fixture, setup),
        slave_(false, setup.slave_fixture, setup) {}

  // Everything logged at or before `log_time_ns` applied; a time earlier than the last one (a
  // seek back) starts again from the beginning of the file.
  void advance_to(std::uint64_t log_time_ns);
  void fill(v1::SupervisorStatus& s) const;

 private:
  static constexpr std::size_t kAlarmsShown = 20;

  struct Side {
    Side(bool is_master, const FixtureParams& fixture, const SummarySetup& setup)
        : is_master_side(is_master),
          builder(is_master, fixture.position_m, fixture.stiffness_N_per_m),
          oscillation(setup.period_s, 0.5, setup.oscillation_threshold_m),
          passivity(setup.period_s) {}
    void reset();
    void add(const v1::Telemetry& t, std::uint64_t log_time_ns);
    void fill(v1::NodeSummary& out, std::int64_t now_ns) const;

    bool is_master_side;
    supervisor::NodeSummaryBuilder builder;
    supervisor::OscillationMonitor oscillation;
    supervisor::PassivityObserver passivity;
    std::uint64_t session_id{0};
  };

  void reset();
  // A message that does not decode is left out of the summary (it is still re-published).
  void apply(const Item& it);

  std::vector<Item> items_;
  std::size_t next_{0};
  std::uint64_t applied_until_ns_{0};
  Side master_;
  Side slave_;
  std::optional<v1::StabilityReport> report_{};
  std::deque<v1::Alarm> alarms_{};  // newest first
  std::optional<v1::SupervisorStatus> recorded_{};
};

// The messages the summary stream is built from, in log-time order: those of the topics it
// reads whose schema is the one it decodes.
[[nodiscard]] std::vector<ReplaySummary::Item> summary_items(const record::SessionReader& session);

// The stability guard's analysis of `params` at their own round trip: verdict, least damping
// ratio, fixtures, the largest stable fixture stiffnesses and the margins to them.
[[nodiscard]] nlohmann::json guard_analysis_json(const TeleopParams& params);

}  // namespace teleop::ctl
