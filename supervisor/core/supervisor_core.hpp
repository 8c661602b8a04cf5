// SupervisorCore: the supervisor without sockets, threads or a clock of its own. Telemetry,
// requests and the time come in; reports, alarms, status, recorded messages and node commands
// go out as typed values through SupervisorPorts and the session sink. teleop-supervisor
// (supervisor/daemon) owns the sockets and the loop around it; tests drive it with a fake
// clock and fake nodes (tests/unit/supervisor/test_supervisor_core.cpp).
//
// What it does (docs/architecture.md "The supervisor"): analyses the running configuration
// with what the nodes really run (the measured rate and round trip, the parameters in force),
// publishes StabilityReports and Alarms, guards parameter changes (analysed first, applied by
// both nodes at an agreed master sequence, ramped), audits the parameters in force, watches
// heartbeats, overruns, loss, oscillation and passivity, escalates through EscalationLadder
// (warn -> lower the fixtures within the guard -> disengage both nodes), lowers the fixtures
// when the measured round trip makes the model miss its requirement (retried until applied),
// and records the session.
//
// Several task-space axes (the file's axes: n > 1; docs/architecture.md "The supervisor with
// several axes"): the report is the n-axis analysis with every plane's limit, the monitors
// watch every axis and the vector port f . v, a change of plane stiffnesses or gain-matrix
// elements is analysed beside the loop (assess_axes_change, per plane against its exact limit)
// and, when admissible, sent to both nodes as an n-axis RETUNE, whose values in force are then
// audited per element; the ladder lowers every plane as the one-axis one lowers the fixtures
// (a guarded change, lower_planes), and a measured model that misses its requirement
// disengages both nodes.
// One axis takes today's path exactly.
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/config/system_compiler.hpp"
#include "common/record/session.hpp"
#include "supervisor/core/axes_supervision.hpp"
#include "supervisor/core/escalation.hpp"
#include "supervisor/core/monitors.hpp"
#include "supervisor/core/monitors_axes.hpp"
#include "supervisor/core/parameter_audit.hpp"
#include "supervisor/core/stability_guard.hpp"
#include "supervisor/core/status_builder.hpp"
#include "teleop/v1/config.pb.h"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::supervisor {

enum class Side { kMaster, kSlave };

// What the core does to the world. The daemon sends these over its sockets; tests collect them.
class SupervisorPorts {
 public:
  virtual ~SupervisorPorts() = default;
  // A command to one node and its reply; none when the node did not answer in time.
  virtual std::optional<v1::NodeCommandReply> command(Side node, const v1::NodeCommand& c) = 0;
  // For consoles (the report endpoint's topics "report", "alarm" and "status").
  virtual void report(const v1::StabilityReport& r) = 0;
  virtual void alarm(const v1::Alarm& a) = 0;
  virtual void status(const v1::SupervisorStatus& s) = 0;
  // For live viewers (`teleopctl bridge`, the report endpoint's topics "config" and
  // "parameter_change"): the configuration in force (config_in_force(): at start, at once when
  // the parameters in force change, and again every kConfigRepeatNs for viewers that joined
  // later) and each parameter change the guard decided, as the session records it. A port that
  // serves no viewer ignores them.
  virtual void config(const v1::SystemConfig& c) { (void)c; }
  virtual void parameter_change(const v1::ParameterChangeRecord& r) { (void)r; }
};

struct SupervisorOptions {
  std::unique_ptr<record::SessionSink> sink{};  // none: no recording
  // Starts a new session file on request (a console's "start recording"); none: refused.
  std::function<std::unique_ptr<record::SessionSink>()> new_sink{};
  std::string record_dir{};
  std::string log_file{};  // rotating log file; empty: terminal only
  // Recording was asked for but could not start (e.g. a read-only record directory): why.
  // The supervisor then supervises without recording and raises a CRITICAL alarm at start.
  std::string record_failure{};
  std::uint32_t pid{0};  // reported in status
  // Added to the core's clock for the log time of what it records: the daemon gives
  // CLOCK_REALTIME - CLOCK_MONOTONIC at start, so session log times are UTC (0: the core's
  // clock, as tests drive it).
  std::int64_t log_time_offset_ns{0};
  // The configuration file as read, attached to each session file ("": the loaded
  // configuration in text format).
  std::string config_text{};
  // A replay of a recorded session (`teleopctl replay`): the core watches the recorded
  // telemetry as the live supervisor watched it -- the same node views, monitors and
  // summaries -- and shows the recorded report, alarms and recording figures (replay_*())
  // instead of its own. It never commands a node, raises an alarm, publishes a report or
  // records; tick() only moves its clock.
  bool replay{false};
};

// Timings of the supervisor's own checks.
inline constexpr std::int64_t kCheckPeriodNs = 100'000'000;      // the checks, 10 per second
inline constexpr std::int64_t kHeartbeatNs = 500'000'000;        // a node silent this long
inline constexpr std::int64_t kRoundTripHoldNs = 5'000'000'000;  // the model's round trip down
inline constexpr std::int64_t kLoweringRetryNs = 200'000'000;    // a refused lowering again
inline constexpr std::int64_t kConfigRepeatNs = 1'000'000'000;   // the config in force again
// An iteration of the owner's loop later than this after the previous one: the supervisor
// itself stalled (its poll waits at most 20 ms, a status request at most a node command's
// 0.5 s).
inline constexpr std::int64_t kOwnStallNs = 250'000'000;

class SupervisorCore {
 public:
  // The system as config::compile_system (common/config/system_compiler.hpp) makes it: the
  // teleoperator, both nodes' setups and the supervisor's settings, validated once.
  SupervisorCore(config::CompiledSystem system, SupervisorOptions options, SupervisorPorts& ports);
  // compile_system(config), then as above; a file of several axes (axes: n > 1) is supervised
  // as n axes (compile_supervised, supervised_axes_params: axes_supervision.hpp).
  SupervisorCore(const config::LoadedConfig& config, SupervisorOptions options,
                 SupervisorPorts& ports);

  // Records the configuration and the first report; a recorder that could not start is a
  // CRITICAL alarm.
  void start(std::int64_t now_ns);
  // One telemetry message from a node.
  void on_telemetry(Side side, const v1::Telemetry& t, std::int64_t now_ns);
  // One request from a client with this CURVE public key (Z85; empty: plaintext, local).
  [[nodiscard]] v1::SupervisorReply on_request(const v1::SupervisorRequest& req,
                                               const std::string& client_key, std::int64_t now_ns);
  // At every iteration of the owner's loop: the supervisor's own stalls, and every 100 ms the
  // checks (configurations, heartbeats, overruns, loss, the measured model, oscillation and
  // passivity through the ladder, the recorder) and the status for consoles.
  void tick(std::int64_t now_ns);

  // A replay (SupervisorOptions::replay): what the recording says the supervisor published --
  // its report, an alarm, its own status (for the recording's figures).
  void replay_report(const v1::StabilityReport& r) {
    report_ = r;
    report_replayed_ = true;
  }
  void replay_alarm(const v1::Alarm& a);
  void replay_recording(const v1::SupervisorStatus& recorded) { replayed_recording_ = recorded; }
  // The status a console is shown at the time of the newest input, as a status request from
  // a client that may command (never, in a replay) is answered.
  [[nodiscard]] v1::SupervisorStatus status() const;

  [[nodiscard]] const config::NodeSetup& node(Side side) const {
    return system_.node(side == Side::kMaster ? transport::Role::kMaster : transport::Role::kSlave);
  }
  [[nodiscard]] const std::string& report_endpoint() const {
    return system_.supervisor().report_endpoint;
  }
  [[nodiscard]] const std::string& request_endpoint() const {
    return system_.supervisor().request_endpoint;
  }
  [[nodiscard]] const std::vector<std::string>& read_only_keys() const {
    return system_.supervisor().read_only_client_keys;
  }
  [[nodiscard]] EscalationState escalation() const { return ladder_.state(); }
  [[nodiscard]] const LiveInputs& live() const { return live_; }
  [[nodiscard]] const v1::StabilityReport& last_report() const { return report_; }
  // The configuration file as read, with the gains and fixture stiffnesses in force (a guarded
  // change applied, a lowering, or the values adopted from running nodes).
  [[nodiscard]] v1::SystemConfig config_in_force() const;
  [[nodiscard]] bool lowering_pending() const { return lowering_pending_; }
  // The task-space axes supervised: the file's axes (1 for a one-axis file).
  [[nodiscard]] int axes() const { return axes_ ? axes_->params.axes : 1; }

 private:
  // Several axes: the file as read, its n-axis model (supervised_axes_params) and the newest
  // assessment published. None for one axis.
  struct AxesState {
    config::LoadedConfig source;
    TeleopAxesParams params;
    AxesAssessment assessment{};
    // Every assessment made, by (sample rate, round trip samples): nothing else of the model
    // changes live with n > 1 (no change is applied), so a round trip that comes back is not
    // analysed again (with a human band an analysis takes seconds, in the loop).
    std::map<std::pair<double, int>, AxesAssessment> assessed{};
    // What both nodes of this file compute (config::axes_control_fingerprint).
    std::uint64_t fingerprint{0};
  };
  [[nodiscard]] static std::optional<AxesState> axes_state(const config::LoadedConfig& config);
  SupervisorCore(config::CompiledSystem system, std::optional<AxesState> axes,
                 SupervisorOptions options, SupervisorPorts& ports);
  // The configuration as loaded: the file as read (n > 1: not its one-axis view).
  [[nodiscard]] const config::LoadedConfig& source() const {
    return axes_ ? axes_->source : system_.source();
  }

  // One node as the supervisor sees it through its telemetry.
  struct NodeView {
    std::string name;
    Side side{Side::kMaster};
    std::optional<v1::Telemetry> last{};
    std::int64_t last_received_ns{0};
    std::uint64_t session_id{0};
    v1::NodeMode mode{v1::NODE_MODE_UNSPECIFIED};
    std::uint64_t overruns_at_check{0};
    std::int64_t overrun_check_ns{0};
    std::uint64_t lost_at_check{0};
    std::uint64_t accepted_at_check{0};
    std::deque<std::int64_t> cycle_times{};  // for the measured rate
    std::unique_ptr<OscillationMonitor> oscillation{};
    std::unique_ptr<PassivityObserver> passivity{};
    std::unique_ptr<NodeSummaryBuilder> summary{};
    // Several axes: one oscillation monitor per axis, the passivity observer on f . v, and
    // the cycles refused (malformed, or another number of axes).
    std::unique_ptr<OscillationMonitorAxes> oscillation_axes{};
    std::unique_ptr<PassivityObserverAxes> passivity_axes{};
    std::uint64_t refused_cycles{0};
    std::int64_t finding_since_ns{0};
    // Parameters in force that the supervisor did not approve (change number and fields), and
    // when it last e-stopped the nodes for them.
    std::string unapproved{};
    std::int64_t unapproved_estop_ns{0};
    std::uint64_t newest_change_seen{0};  // this session's
    bool rt_recorded{false};              // its RT settings in the session file's metadata
  };
  // A monitor's finding on one node at one check.
  struct Finding {
    std::string what;  // "" none
    std::string kind;  // the alarm's kind: "oscillation" or "passivity"
    std::vector<std::tuple<std::string, double, std::string>> evidence;
  };
  // What lowering the fixtures came to.
  struct Lowering {
    bool applied{false};
    std::string action;  // said in the alarm
  };
  using Evidence = std::vector<std::tuple<std::string, double, std::string>>;

  // supervisor_core.cpp: messages out, telemetry, changes, requests, status.
  void record(std::string_view topic, const google::protobuf::Message& m);
  // The log time of what is recorded now (the core's clock + log_time_offset_ns).
  [[nodiscard]] std::int64_t log_time_ns() const { return now_ns_ + opts_.log_time_offset_ns; }
  // Metadata and the configuration attachment, at the start of each session file.
  void record_start();
  std::optional<v1::NodeCommandReply> command(Side side, v1::NodeCommand::Kind kind);
  [[nodiscard]] std::uint64_t master_sequence() const;
  [[nodiscard]] v1::StabilityReport make_report(const Assessment& a,
                                                const std::string& reason) const;
  void publish_report(const std::string& reason);
  // config_in_force() to the ports when it differs from the last sent or kConfigRepeatNs
  // passed since.
  void publish_config();
  // A change decided (applied or refused, dry run or not): recorded and published.
  void change_decided(const v1::ParameterChangeRecord& rec);
  void alarm(v1::Alarm::Severity severity, const std::string& kind, const std::string& side,
             const std::string& message, const Evidence& evidence, const std::string& action = "");
  v1::ParameterChangeReply apply_change(const ChangeRequest& change, bool dry_run,
                                        const std::string& why);
  [[nodiscard]] v1::ParameterUpdate make_update(const LiveInputs& proposed, std::uint64_t id,
                                                std::uint64_t at) const;
  struct Delivery {
    std::string refusal;      // "" when both took it, else who did not and why
    bool master_took{false};  // or may have: it did not answer
  };
  [[nodiscard]] Delivery send_to_both(const v1::NodeCommand& c);
  std::string roll_back(std::uint64_t refused_id, const std::string& refusal);
  void on_change_request(const v1::ParameterChangeRequest& c, v1::SupervisorReply& reply);
  void audit_parameters(NodeView& n, const v1::Telemetry& t);
  // supervisor_axes.cpp: several axes.
  void publish_axes_report(const std::string& reason);
  void feed_axes_monitors(NodeView& n, const v1::Telemetry& t);
  [[nodiscard]] Finding axes_finding(NodeView& n) const;
  [[nodiscard]] MonitorReadings axes_readings(const NodeView& n) const;
  void refuse_axes_change(const v1::ParameterChangeRequest& c, v1::SupervisorReply& reply);
  // A guarded n-axis change (plane stiffnesses, gain elements): checked at once, analysed by
  // assess_axes_change on a thread of its own (seconds with a human band: the loop, status and
  // e-stop keep answering), decided and applied by finish_axes_change() from tick().
  struct AxesChange {
    v1::ParameterChangeRequest request;
    std::uint64_t request_id{0};
    TeleopAxesParams proposed;
    std::future<AxesDecision> decision;
  };
  void request_axes_change(const v1::ParameterChangeRequest& c, v1::SupervisorReply& reply);
  void finish_axes_change();
  void apply_axes_change(const AxesChange& change, const AxesDecision& d,
                         v1::ParameterChangeReply& reply);
  void axes_change_decided(const v1::ParameterChangeRequest& c,
                           const v1::ParameterChangeReply& reply);
  // The n-axis model in force at the measured rate and round trip; `c` applied to it ("" or the
  // refusal naming the field).
  [[nodiscard]] TeleopAxesParams axes_in_force() const;
  // The file as read with the n-axis gains (as matrices) and plane stiffnesses in force; the
  // file itself, byte for byte, until a change applied.
  [[nodiscard]] v1::SystemConfig axes_config_in_force() const;
  [[nodiscard]] std::string propose_axes(const v1::ParameterChangeRequest& c,
                                         TeleopAxesParams& proposed) const;
  // The RETUNE's update for the n-axis values of `p` (gain matrices, plane stiffnesses).
  [[nodiscard]] v1::ParameterUpdate axes_update(const TeleopAxesParams& p, std::uint64_t id,
                                                std::uint64_t at) const;
  [[nodiscard]] std::string axes_configuration_mismatch() const;
  void adopt_parameters_in_force(const v1::Telemetry& t);
  void adopt_axes_parameters_in_force(const v1::Telemetry& t);
  void handle_request(const v1::SupervisorRequest& req, v1::SupervisorReply& reply);
  [[nodiscard]] std::string read_only_refusal(const v1::SupervisorRequest& req,
                                              const std::string& key) const;
  v1::NodeCommandResult forward_node_command(const v1::NodeCommandRequest& r);
  void set_recording(bool on, v1::SupervisorReply& reply);
  void fill_status(v1::SupervisorStatus& s, bool may_command) const;
  void fill_configuration_status(v1::SupervisorStatus& s) const;

  // supervisor_checks.cpp: the 100 ms checks.
  void excuse_own_stall();
  void check_live();
  void check_configurations();
  void check_heartbeats(NodeView& n);
  void update_model();
  void retry_lowering();
  void check_findings();
  [[nodiscard]] Finding finding(NodeView& n) const;
  // `why`: what the alarm says happened before (the one-axis ladder: the lowering).
  void disengage_both(const NodeView& n, const Finding& f,
                      const std::string& why = "persisted after lowering the fixtures");
  Lowering lower_fixtures(const std::string& why);
  Lowering lower_planes(const std::string& why);
  void announce_lowering(const Lowering& l, const char* suffix);
  void check_recorder();

  SupervisorPorts& ports_;
  config::CompiledSystem system_;
  TeleopParams params_;
  StabilityGuard guard_;
  ParameterAudit audit_;
  SupervisorOptions opts_;
  double oscillation_threshold_m_{0.0};
  double passivity_threshold_J_{0.0};
  double passivity_power_threshold_W_{0.0};
  std::int64_t escalation_ns_{0};
  double change_ramp_ms_{200.0};
  double period_s_{0.001};

  std::int64_t now_ns_{0};  // the time of the input being handled
  std::int64_t next_check_ns_{0};
  std::int64_t last_iteration_ns_{0};
  std::uint64_t checks_{0};
  NodeView master_{};
  NodeView slave_{};
  LiveInputs live_{};
  std::int64_t measured_round_trip_ns_{0};
  RoundTripModel round_trip_model_{kRoundTripHoldNs};
  // The round-trip guard's lowering was refused (retried every kLoweringRetryNs).
  bool lowering_pending_{false};
  std::int64_t last_lowering_try_ns_{0};
  // Why the pending lowering is wanted (said again when it is retried).
  std::string lowering_why_{"the measured round trip or rate changed"};
  EscalationLadder ladder_{0, 0};
  std::uint64_t change_id_{0};
  std::uint64_t last_sent_change_id_{0};  // the newest change number sent, taken or not
  v1::StabilityReport report_{};
  std::string published_config_{};  // config_in_force() as last sent to the ports
  std::int64_t config_published_ns_{0};
  std::deque<v1::Alarm> recent_alarms_{};
  std::map<std::string, std::int64_t> last_alarm_ns_{};
  bool heard_master_{false};
  std::string configuration_mismatch_{};  // "" while the supervisor and both nodes agree
  bool recorder_failure_announced_{false};
  bool recording_file_lost_announced_{false};
  std::optional<v1::SupervisorStatus> replayed_recording_{};  // replay_recording()
  std::optional<AxesState> axes_{};                           // several axes only
  std::optional<AxesChange> axes_change_{};      // the n-axis change being analysed, if any
  std::uint64_t axes_requests_{0};               // n-axis change requests numbered so far
  v1::ParameterChangeReply last_axes_change_{};  // the newest decided (status.last_change)
  bool report_replayed_{false};  // a replay shows a report only once one was recorded
};

}  // namespace teleop::supervisor
