// A RETUNE's update as a node's RT core takes it, and what the core runs as telemetry's
// ActiveParameters (docs/nodes.md "Guarded parameter changes", "n task-space axes"): for one
// axis (NodeCore) and for several (NodeCoreAxes). Command and telemetry threads only.
#pragma once

#include <optional>
#include <string>

#include "common/node/node_core.hpp"
#include "common/node/node_core_axes.hpp"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::runtime {

// The update as the core takes it; nullopt with the reason (naming the field) when a value is
// unusable or the update does not fit this node (the one parameter space,
// common/config/parameter_space.hpp).
[[nodiscard]] std::optional<node::Retune> retune_of(const node::NodeCore& core,
                                                    const teleop::v1::ParameterUpdate& u,
                                                    std::string& why);
[[nodiscard]] std::optional<node::RetuneAxes> retune_of(const node::NodeCoreAxes& core,
                                                        const teleop::v1::ParameterUpdate& u,
                                                        std::string& why);

// What the law runs, as Telemetry.active.
void fill_active(teleop::v1::ActiveParameters& a, const node::ActiveLaw& active);
void fill_active(teleop::v1::ActiveParameters& a, const node::ActiveLawAxes& active);

}  // namespace teleop::runtime
