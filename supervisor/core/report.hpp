// The StabilityReport message of an Assessment: one definition for the live supervisor and for
// `teleopctl simulate --out` (which writes what the supervisor would have published).
#pragma once

#include <cstdint>
#include <string>

#include "supervisor/core/stability_guard.hpp"
#include "teleop/v1/supervisor.pb.h"

namespace teleop::supervisor {

struct ReportContext {
  std::int64_t time_ns{0};
  std::uint64_t master_sequence{0};
  std::int64_t measured_round_trip_ns{0};
  std::string reason{};
  std::uint64_t parameter_change_id{0};
};

[[nodiscard]] v1::Gains to_proto(const Gains& g);
[[nodiscard]] v1::StabilityReport to_report(const Assessment& a, const ReportContext& context);

}  // namespace teleop::supervisor
