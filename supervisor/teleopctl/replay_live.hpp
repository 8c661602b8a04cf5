// `teleopctl replay FILE.mcap --speed X`: a recorded session re-published as if live (telemetry
// on the nodes' telemetry endpoints, reports and alarms on the supervisor's report endpoint),
// paced by the recorded log times, with a control endpoint (pause, resume, toggle, seek, speed,
// status, stop) and the supervisor's summary stream ten times a second.
#pragma once

#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "common/core/defaults.hpp"
#include "common/session/session_reader.hpp"

namespace teleop::ctl {

struct LiveReplayOptions {
  std::string file{};  // as given, for the summary stream's replay position
  double speed{1.0};
  std::string control{defaults::kReplayControlEndpoint};
  // Unset: the recorded configuration's endpoint, else the default.
  std::optional<std::string> master_endpoint{};
  std::optional<std::string> slave_endpoint{};
  std::optional<std::string> report_endpoint{};
  bool start_paused{false};
  bool hold{false};                      // at the end, keep the control endpoint up until "stop"
  std::vector<std::string> overrides{};  // --set, on the recorded configuration
};

// Runs until the end of the file (or "stop" with `hold`); prints where it publishes at the
// start and the final status at the end on `out`. Throws std::runtime_error naming an endpoint
// that cannot be bound, or a configuration error.
int replay_live(const record::SessionReader& session, const LiveReplayOptions& options,
                std::ostream& out, std::ostream& err);

}  // namespace teleop::ctl
