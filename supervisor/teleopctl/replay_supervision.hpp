// What `teleopctl replay` asks of the supervisor's logic (supervisor/core, never the daemon):
// the summary stream a replay publishes, the recorded telemetry fed through SupervisorCore as
// the supervisor feeds live telemetry, and the guard's analysis of a set of parameters.
#pragma once

#include <cstddef>
#include <cstdint>
#include <iosfwd>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string_view>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/config/system_compiler.hpp"
#include "common/core/teleop_params.hpp"
#include "common/session/session_reader.hpp"
#include "supervisor/core/supervisor_core.hpp"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::ctl {

// What the summary stream shows at a position of the replay: the file's messages up to that
// log time fed through the supervisor's own core (SupervisorCore in its replay mode: the same
// node views, monitors and summaries as live, with the recorded report, alarms and recording
// figures), with the recorded log times for its clock.
class ReplaySummary {
 public:
  enum Kind { kMaster = 0, kSlave = 1, kReport = 2, kAlarm = 3, kRecordedStatus = 4 };
  struct Item {
    Kind kind{kMaster};
    std::uint64_t log_time_ns{0};
    std::string_view data{};  // valid while the session file is open
  };

  // `config`: the recorded configuration (with any --set applied). Without one, or when it
  // does not describe the teleoperator (said on `err`), the papers' paddles without fixtures
  // stand in for it: the monitors then use the default period and thresholds.
  ReplaySummary(const std::optional<config::LoadedConfig>& config, std::vector<Item> items,
                std::ostream& err);

  // Everything logged at or before `log_time_ns` applied; a time earlier than the last one (a
  // seek back) starts again from the beginning of the file.
  void advance_to(std::uint64_t log_time_ns);
  // The core's summary, with each node of n > 1 task-space axes (issue 18) given its newest
  // cycle per axis (NodeSummary.axes, positions_m, forces_N, commands_N, tracking_errors_m =
  // alpha x_m - x_s, alpha the configuration's position scaling).
  [[nodiscard]] v1::SupervisorStatus status() const;

 private:
  // A replay commands nothing and publishes through its own sockets, not the core's.
  class NoPorts final : public supervisor::SupervisorPorts {
   public:
    std::optional<v1::NodeCommandReply> command(supervisor::Side, const v1::NodeCommand&) override {
      return std::nullopt;
    }
    void report(const v1::StabilityReport&) override {}
    void alarm(const v1::Alarm&) override {}
    void status(const v1::SupervisorStatus&) override {}
  };

  void reset();
  // A message that does not decode is left out of the summary (it is still re-published).
  void apply(const Item& it);

  config::CompiledSystem system_;
  std::vector<Item> items_;
  NoPorts ports_{};
  std::unique_ptr<supervisor::SupervisorCore> core_{};
  std::size_t next_{0};
  std::uint64_t applied_until_ns_{0};
};

// The messages the summary stream is built from, in log-time order: those of the topics it
// reads whose schema is the one it decodes.
[[nodiscard]] std::vector<ReplaySummary::Item> summary_items(const record::SessionReader& session);

// The stability guard's analysis of `params` at their own round trip: verdict, least damping
// ratio, fixtures, the largest stable fixture stiffnesses and the margins to them.
[[nodiscard]] nlohmann::json guard_analysis_json(const TeleopParams& params);

}  // namespace teleop::ctl
