// The summary of `teleopctl replay FILE.mcap` (its default action): duration, channels with
// message counts and schemas, recorder drops when known, node cycles and cycles missing, the
// nodes' wake-up latency and overruns, alarms, parameter changes and the stability margin over
// time; as JSON (--json) or as text.
#pragma once

#include <iosfwd>
#include <nlohmann/json.hpp>

#include "common/session/session_reader.hpp"

namespace teleop::ctl {

// Throws as SessionReader::visit does (a message that does not decode as its topic's type).
[[nodiscard]] nlohmann::json summary_json(const record::SessionReader& session);

// The text form of summary_json's result.
void print_summary(const nlohmann::json& j, std::ostream& out);

}  // namespace teleop::ctl
