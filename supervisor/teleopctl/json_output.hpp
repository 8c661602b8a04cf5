// The JSON documents teleopctl prints (analyze's fields documented in docs/analyze.md).
#pragma once

#include <google/protobuf/message.h>

#include <nlohmann/json.hpp>
#include <optional>

#include "common/core/teleop_params.hpp"
#include "common/stability/analyzer.hpp"
#include "common/stability/force_loop.hpp"
#include "common/stability/stiffness_search.hpp"

namespace teleop::ctl {

// A protobuf message as teleopctl prints it under --json: its proto field names (snake_case,
// units as in the .proto: `stiffness_N_per_m`), every field present, one line.
[[nodiscard]] nlohmann::json proto_json(const google::protobuf::Message& message);

[[nodiscard]] nlohmann::json human_json(const std::optional<stability::HumanSample>& human);
[[nodiscard]] nlohmann::json mode_json(const stability::Mode& mode);
[[nodiscard]] nlohmann::json analysis_json(const stability::AnalysisResult& result,
                                           const TeleopParams& params);
[[nodiscard]] nlohmann::json limit_json(const stability::StiffnessLimit& limit,
                                        stability::Side side, double sample_rate_hz);
[[nodiscard]] nlohmann::json force_loop_json(const stability::ForceLoopResult& result,
                                             const ForceLoopParams& params);

}  // namespace teleop::ctl
