// `teleopctl set PATH=VALUE...`: a guarded parameter change through the supervisor, which
// analyses it first and applies it only if the predicted teleoperator stays stable with the
// required damping (issue 5 "Guards parameters"). PATH: gains.kpm ... gains.kfm,
// master.fixture.stiffness_N_per_m, slave.fixture.stiffness_N_per_m; with several axes
// master.planes[I].stiffness_N_per_m, slave.planes[I].stiffness_N_per_m and gains.kps[I,J].
#pragma once

#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include "supervisor/teleopctl/cli_args.hpp"
#include "teleop/v1/supervisor.pb.h"

namespace teleop::ctl {

[[nodiscard]] std::string set_usage();

// "PATH=VALUE" -> (PATH, VALUE); UsageError naming what is wrong (unknown path, bad number).
[[nodiscard]] std::pair<std::string, double> parse_setting(const std::string& text);
// The change request for these settings; `gains_in_force` completes a change of some gains.
[[nodiscard]] v1::ParameterChangeRequest make_change_request(
    const std::vector<std::pair<std::string, double>>& settings, const v1::Gains& gains_in_force,
    bool dry_run, const std::string& requested_by);
// Several axes: plane stiffnesses and gain elements (a scalar gain is that gain on every axis);
// UsageError for a one-axis fixture path.
[[nodiscard]] v1::ParameterChangeRequest make_axes_change_request(
    const std::vector<std::pair<std::string, double>>& settings, bool dry_run,
    const std::string& requested_by);
int run_set(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

// Where and how a client reaches the supervisor: --supervisor HOST:PORT (request endpoint),
// --key FILE (this client's key pair), --server-key KEY|FILE, --timeout-ms N.
struct SupervisorClientFlags {
  std::string endpoint{"tcp://127.0.0.1:5567"};
  std::string key{};
  std::string server_key{};
  int timeout_ms{2000};
  bool endpoint_given{false};  // --supervisor was on the command line
  bool timeout_given{false};   // --timeout-ms was on the command line
  // Takes the cursor's current flag (and its value) if it is one of these; false otherwise.
  bool take(ArgCursor& cur);
  // Neither --key nor --server-key: the keys of a live `teleopctl launch` whose supervisor
  // is at `endpoint` (local_launch.hpp), if there is one.
  void use_local_launch_keys();
};

// One request to the supervisor; nullopt when no reply came within timeout_ms.
[[nodiscard]] std::optional<v1::SupervisorReply> supervisor_request(
    const std::string& endpoint, const v1::SupervisorRequest& request, int timeout_ms,
    const std::string& secret_key_file = "", const std::string& server_key = "");
// The same to the supervisor `sup` names, with its keys and timeout.
[[nodiscard]] std::optional<v1::SupervisorReply> supervisor_request(
    const SupervisorClientFlags& sup, const v1::SupervisorRequest& request);
// Its status: the reply to a status request (nullopt as above).
[[nodiscard]] std::optional<v1::SupervisorReply> supervisor_status(
    const SupervisorClientFlags& sup);

}  // namespace teleop::ctl
