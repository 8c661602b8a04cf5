// What a session file holds beyond the messages the supervisor publishes (issue 17, docs/
// supervisor.md "Sessions"): every cycle on its own channel, alarms as foxglove.Log, and the
// Metadata records and the configuration Attachment written at start. Used by SupervisorCore
// (live sessions) and `teleopctl simulate --out` (simulated ones), so both files look alike.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <string_view>

#include "common/config/config_loader.hpp"
#include "common/record/session.hpp"
#include "foxglove/Log.pb.h"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::supervisor {

// Each cycle of `t` (not its flight record) on /master/cycle or /slave/cycle: the
// teleop.v1.CycleRecord with the telemetry's session_id, publish_time = its sample_time_ns
// (the node's monotonic clock) and log_time spread back from `log_time_ns` (when the batch
// arrived) by the cycles' sample-time spacing: the newest cycle at log_time_ns, one 1 ms
// earlier at log_time_ns - 1 ms, ..., so a plot against log time keeps the 1 kHz spacing.
void record_cycles(record::SessionSink& sink, bool master, const v1::Telemetry& t,
                   std::int64_t log_time_ns);

// An alarm as Foxglove's Log panel shows it (severity mapping in common/record/session.hpp).
[[nodiscard]] foxglove::Log to_foxglove_log(const v1::Alarm& a, std::int64_t log_time_ns);

// The "teleop" metadata: version, host, configuration file and fingerprint, who recorded it,
// when it started (UTC) and which clock the log times are on.
[[nodiscard]] std::map<std::string, std::string> teleop_metadata(const config::LoadedConfig& config,
                                                                 std::string_view recorder,
                                                                 std::int64_t start_utc_ns);
// The "teleop.analysis" metadata: the report at start.
[[nodiscard]] std::map<std::string, std::string> analysis_metadata(const v1::StabilityReport& r);
// The "teleop.rt.<node>" metadata: a node's RT settings in force (from its telemetry).
[[nodiscard]] std::map<std::string, std::string> rt_metadata(const v1::RtStatus& rt);

// Writes the "teleop" and "teleop.analysis" metadata and the configuration as the
// config.textproto Attachment: `config_text` as read from the file, or (empty) the loaded
// configuration in text format.
void record_session_start(record::SessionSink& sink, const config::LoadedConfig& config,
                          const std::string& config_text, const v1::StabilityReport& start,
                          std::string_view recorder, std::int64_t log_time_ns);

// The wall clock (CLOCK_REALTIME), ns since the epoch, UTC.
[[nodiscard]] std::int64_t wall_clock_ns();

}  // namespace teleop::supervisor
