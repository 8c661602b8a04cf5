// The supervisor of an n-axis teleoperator (issue 18 "Everything above the law";
// docs/architecture.md "The supervisor with several axes"): what SupervisorCore adds when the
// file says axes: n > 1. Setup and check code, never on a node's real-time path.
//
// The supervisor's settings, endpoints and node setups are compiled as for one axis, from the
// file's one-axis view (one_axis_view: the n-axis fields taken out, axis 0's values in the
// scalars), while the stability report, the monitors and the change requests use the n-axis
// teleoperator (config::to_axes_params) of the file as read.
#pragma once

#include <string>

#include "common/config/config_loader.hpp"
#include "common/config/system_compiler.hpp"
#include "common/core/teleop_axes.hpp"
#include "supervisor/core/report.hpp"
#include "supervisor/core/stability_guard_axes.hpp"
#include "teleop/v1/supervisor.pb.h"

namespace teleop::supervisor {

// Whether the supervisor takes the n-axis path for this file: SystemConfig.axes > 1.
[[nodiscard]] bool several_axes(const config::LoadedConfig& config) noexcept;

// The file with every n-axis field removed (axes, mass matrices, per-axis damping and friction,
// kinematics, fixture planes, per-axis and matrix gains, per-axis human bands, the scene's
// n-axis fields), the scalars holding axis 0's values where the file gave only the n-axis
// form. compile_system takes it: the supervisor's settings and both nodes' endpoints are the
// file's; nothing analysed comes from it.
[[nodiscard]] config::LoadedConfig one_axis_view(const config::LoadedConfig& config);

// The system the supervisor runs on: compile_system(config) for one axis (today's path
// exactly), compile_system(one_axis_view(config)) for several. Throws ConfigError.
[[nodiscard]] config::CompiledSystem compile_supervised(const config::LoadedConfig& config);

// The n-axis model the supervisor analyses: the file's, at a round trip of at least one sample
// (two free-running loops always add one, as the one-axis supervisor assumes).
[[nodiscard]] TeleopAxesParams supervised_axes_params(const config::LoadedConfig& config);

// The StabilityReport of an n-axis assessment of `params` (StabilityReport.axes, planes,
// worst_human_per_axis; the one-axis fields left unset).
[[nodiscard]] v1::StabilityReport to_report(const AxesAssessment& a, const TeleopAxesParams& params,
                                            const ReportContext& context);

}  // namespace teleop::supervisor
