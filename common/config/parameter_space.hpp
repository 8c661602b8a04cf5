// The one parameter space (issue 14): every numeric parameter of the teleoperator, wherever it
// comes from — a configuration file, a `--set`, `teleopctl set` through the supervisor, or a
// RETUNE on a node's command endpoint — is checked here, by the same rules:
//   - finite (protobuf's text parser and wire format both carry nan and inf);
//   - the sign and the physical range documented next to the field in config.proto, with a
//     ceiling per field a haptics engineer would never need to exceed (and far below the
//     values that overflow the stability model);
//   - endpoints: tcp://HOST:PORT with PORT in 1-65535 (or ipc://PATH, inproc://NAME), and every
//     endpoint a process binds (both nodes' state, command and telemetry, the supervisor's
//     report and request) distinct from every other.
// Setup and command-handling code only: allocates, never called from the real-time thread.
#pragma once

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

#include <string>
#include <string_view>
#include <vector>

#include "teleop/v1/config.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::config {

// The range of one numeric field: value in [min, max] (or (min, max] when min_exclusive).
struct FieldRule {
  double min{0.0};
  double max{0.0};
  bool min_exclusive{false};
  std::string_view unit{};  // e.g. "N/m", for messages
  std::string_view why{};   // the ceiling's justification, for messages
};

// The rule of a field (by its protobuf descriptor), or nullptr for fields without one (strings,
// enums, positions checked only for finiteness, ...).
[[nodiscard]] const FieldRule* rule_for(const google::protobuf::FieldDescriptor* field);

// The full protobuf names of every field with a rule (for tests: each must exist).
[[nodiscard]] std::vector<std::string_view> ruled_fields();

// Empty when `value` is acceptable for `field`, else the reason, e.g.
// "must be <= 1e+07 N/m (...), got 1e+308" or "must be finite, got nan".
[[nodiscard]] std::string check_value(const google::protobuf::FieldDescriptor* field, double value);

struct FieldProblem {
  std::string path{};     // dotted from the message checked, with [i] for elements
  std::string message{};  // what check_value says
};

// Every numeric field of `message`, recursively: repeated elements, fields with presence when
// set, plain proto3 scalars always for finiteness and, when not 0 (their default), for range.
[[nodiscard]] std::vector<FieldProblem> check_fields(const google::protobuf::Message& message);

// The gains, fixtures and ramp of a live parameter change, by the rules of the configuration's
// own fields (gains.*, *.fixture.*): "" when acceptable, else one line per problem, each naming
// the field. Used by the supervisor before it analyses a change and by a node before it applies
// a RETUNE.
[[nodiscard]] std::string check_parameter_update(const teleop::v1::ParameterUpdate& update);

// The same for a teleoperator of `axes` > 1 task-space axes with these many fixture planes a
// side (a RETUNE to an n-axis node, and the supervisor's before it sends one): the update's axes
// must be `axes`; one stiffness per plane of each side, in [0, 1e7] N/m; the one-axis fixture
// fields 0; the gains by the configuration's rules (config::gains_axes_of: scalar, diagonal or
// n x n matrix, symmetric positive semidefinite); ramp_ms as above. "" when acceptable, else
// one line per problem, each naming the field.
[[nodiscard]] std::string check_parameter_update_axes(const teleop::v1::ParameterUpdate& update,
                                                      int axes, int master_planes,
                                                      int slave_planes);

// "" when `gains` holds only the one-axis scalars, else one line per per-axis list or matrix
// given, naming it: a live change is one axis (the nodes run one), and the supervisor and the
// nodes refuse such fields rather than drop them.
[[nodiscard]] std::string check_one_axis_gains(const teleop::v1::Gains& gains);

// "" when `endpoint` can be bound (tcp://HOST:PORT, PORT 1-65535; ipc://PATH; inproc://NAME),
// else the reason.
[[nodiscard]] std::string check_endpoint(std::string_view endpoint);

// The endpoints a configuration makes processes bind, defaults filled in, with their field
// paths: master/slave .node.{state,command,telemetry}_endpoint and supervisor.{report,
// request}_endpoint.
struct BoundEndpoint {
  std::string path{};
  std::string endpoint{};
  bool defaulted{false};
};
[[nodiscard]] std::vector<BoundEndpoint> bound_endpoints(const teleop::v1::SystemConfig& config);

// Whether two endpoints would bind the same socket (the same port on the same address, or on
// every address; the same ipc path).
[[nodiscard]] bool endpoints_clash(std::string_view a, std::string_view b);

}  // namespace teleop::config
