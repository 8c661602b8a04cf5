// The supervisor's audit of the parameters in force (issue 14 "Authority"): every node's
// telemetry carries what its law runs (ActiveParameters: change id, gains, fixture
// stiffnesses, ramp progress); the supervisor compares it with what it approved, i.e. the
// file's values (change 0) and every change it sent itself. Anything else in force (a RETUNE
// that reached a node without the supervisor, a change number it never sent) is a mismatch,
// and the supervisor raises a CRITICAL alarm and drives the nodes safe.
//
// Its own changes never read as a mismatch: a change is approved before it is sent, so the old
// values stay approved while the nodes wait for the apply point, and during a ramp
// (ramp_progress < 1) each value only has to lie between approved values (the node ramps
// linearly from the values in force, which were approved, to approved ones). Settled
// (ramp_progress 1), the values must be those of the change in force, or of a later approved
// change (a node takes a newer target into a ramp under way). With several axes the same holds
// for every gain-matrix element and every plane's stiffness (ActiveParameters.axes > 0).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "common/core/teleop_params.hpp"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::supervisor {

struct ApprovedParameters {
  Gains gains{};
  double master_fixture_N_per_m{0.0};
  double slave_fixture_N_per_m{0.0};
  // Several axes (axes > 1): every gain-matrix element and plane stiffness, named as the audit
  // names what a node reports (approved_axes()); the one-axis fields above are then unused.
  int axes{0};
  std::vector<std::pair<std::string, double>> axes_values{};
};

// The approved values of an n-axis teleoperator: `gains` as its seven n x n matrices
// (kpm_matrix ... kfm_matrix, row-major) and each side's plane stiffnesses, named
// "gains.kps[0,1]", "slave.planes[1].stiffness_N_per_m", ...
[[nodiscard]] ApprovedParameters approved_axes(
    int axes, const v1::Gains& gains,
    const google::protobuf::RepeatedField<double>& master_planes_N_per_m,
    const google::protobuf::RepeatedField<double>& slave_planes_N_per_m);

struct ParameterMismatch {
  std::string field{};         // "change_id", "gains.kps", "slave_fixture_stiffness_N_per_m",
                               // "gains.kps[0,0]", "slave.planes[1].stiffness_N_per_m", ...
  double in_force{0.0};        // as the node reports it
  double approved{0.0};        // what the supervisor approved for it (the change's, or the nearest
                               // approved bound during a ramp)
  std::uint64_t change_id{0};  // the change the node says is in force
  std::string why{};           // one line
};

class ParameterAudit {
 public:
  // Change 0: the configuration file's values.
  explicit ParameterAudit(const ApprovedParameters& file_values);

  // Called before a change is sent (so the nodes' acknowledgement can never race it). A change
  // number is approved once: approving it again with other values throws std::logic_error (a
  // reused number could not be told apart in telemetry).
  void approve(std::uint64_t change_id, const ApprovedParameters& p);
  // A change found in force by a supervisor (re)started on running nodes, adopted as approved.
  void adopt(std::uint64_t change_id, const ApprovedParameters& p);
  [[nodiscard]] bool approved(std::uint64_t change_id) const {
    return approved_.count(change_id) != 0;
  }
  [[nodiscard]] std::uint64_t newest() const { return approved_.rbegin()->first; }

  // Empty when `active` is approved; otherwise every field that is not. `newest_seen`: the
  // newest change this node has been seen running (this session); an older one in force now
  // (an old approved change replayed) is a mismatch too.
  [[nodiscard]] std::vector<ParameterMismatch> check(const v1::ActiveParameters& active,
                                                     std::uint64_t newest_seen = 0) const;

 private:
  std::map<std::uint64_t, ApprovedParameters> approved_;
};

// One line for an alarm: "gains.kps 9000 in force (approved 600), ..." for every mismatch.
[[nodiscard]] std::string describe(const std::vector<ParameterMismatch>& m);

}  // namespace teleop::supervisor
