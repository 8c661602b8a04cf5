// `teleopctl simulate SCENE --out FILE.mcap` for a scene of several task-space axes (issue 18;
// docs/simulate.md "Session files"): the n-axis lockstep run written as the live n-axis nodes
// and supervisor record a session.
#pragma once

#include <cstdint>
#include <string>

#include "common/config/config_loader.hpp"
#include "common/scene/lockstep_axes.hpp"

namespace teleop::ctl {

// Runs `setup` (simulate_axes, the rows as it keeps them) and writes every cycle of both nodes to
// `path`: /config, /supervisor/stability (the n-axis report of the loop the run plays), the
// metadata and the scene as the configuration attachment at `start_ns`, then /master/telemetry
// and /slave/telemetry (kCyclesPerMessage cycles per message, the n-axis CycleRecord fields of
// common/telemetry/cycle_codec.hpp) and /master/cycle and /slave/cycle. Cycle k (sequence
// k + 1, sample time k T) is what each law saw and did at sample k (AxesCycleView): its sensed
// position, load-cell force and filtered velocity, its command (the master's actuator is driven
// by -F_am), the peer state of that sample (the slave's at once, the master's
// round_trip_delay_samples late) and its deepest plane's penetration. Throws naming the file.
[[nodiscard]] scene::AxesSimulationResult simulate_axes_session(const std::string& path,
                                                                const config::LoadedConfig& cfg,
                                                                const scene::AxesSceneSetup& setup,
                                                                std::int64_t start_ns,
                                                                const scene::Progress& progress);

}  // namespace teleop::ctl
