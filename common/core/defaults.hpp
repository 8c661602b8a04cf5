// The shipped defaults: what a node, the supervisor and the tools run with when the
// configuration leaves a field out (config.proto gives each in brackets). The loaders fall back
// to these and the structs that hold the values start from them, so the two cannot disagree.
// Units in the names (SI unless the name says otherwise); durations as std::chrono constants.
#pragma once

#include <chrono>
#include <cstdint>
#include <string_view>

namespace teleop::defaults {

// --- the link and engagement (teleop.v1.Link) ------------------------------------------------

// A peer silent this long sends the node safe.
inline constexpr std::chrono::milliseconds kPeerTimeout{30};
// Safe master: its force ramps to zero over this.
inline constexpr std::chrono::milliseconds kSafeRamp{10};
// Engaged: the coupling force ramps up over this.
inline constexpr std::chrono::milliseconds kEngageRamp{200};
// Coupling starts when |alpha x_m - x_s| is within this.
inline constexpr double kAlignmentTolerance_m = 0.002;
// Aligning: the weak spring guiding the operator's master to the slave, its damping and its
// largest force.
inline constexpr double kCentringStiffness_N_per_m = 30.0;
inline constexpr double kCentringDamping_Ns_per_m = 0.3;
inline constexpr double kCentringMaxForce_N = 0.5;

// --- a node process (teleop.v1.Node, RealTime, Usb) ----------------------------------------

// Telemetry messages per second (each carries every cycle since the last).
inline constexpr double kTelemetryRate_hz = 50.0;
// SCHED_FIFO priority of the loop thread, and mlockall, as a configuration asks by default
// (rt::RtSettings{} itself leaves the scheduler and memory alone).
inline constexpr int kFifoPriority = 80;
inline constexpr bool kLockMemory = true;
// Held in /dev/cpu_dma_latency while the node runs (-1: leave it alone).
inline constexpr int kCpuDmaLatency_us = 10;
// USB ids of the device (placeholders from pid.codes, docs/usb-protocol.md) and its watchdog:
// it zeroes its output when no command arrived for this long.
inline constexpr std::uint16_t kUsbVendorId = 0x1209;
inline constexpr std::uint16_t kUsbProductId = 0x7E1E;
inline constexpr std::chrono::milliseconds kUsbWatchdog{20};

// --- a simulated device (teleop.v1.Device) ---------------------------------------------------

// The paper's paddle hardware (Abbott-Okamura §4.1): 16-bit D/A at +-10 V, 1.65 N/V, and its
// load cell's range.
inline constexpr double kPaddleMaxForce_N = 16.5;
inline constexpr double kPaddleLoadCellRange_N = 10.0;

// --- a simulated scene (teleop.v1.Scene) -----------------------------------------------------

// A malicious user (scene.malicious_user) holds each human of the band this long.
inline constexpr double kMaliciousDwell_s = 1.0;
// The force-device scene's grip between the hand and the handle, and where its tissue starts.
inline constexpr double kGripStiffness_N_per_m = 2000.0;
inline constexpr double kGripDamping_Ns_per_m = 20.0;
inline constexpr double kForceDeviceTissuePosition_m = 0.03;

// --- the analysis (teleop.v1.Human, ForceLoop, Analysis) -------------------------------------

// Grid points per parameter of a human band.
inline constexpr int kBandPointsPerAxis = 4;
// Samples the force-loop device's sensor averages.
inline constexpr int kSensorAverageSamples = 50;
// Stiffness limits are searched to within this.
inline constexpr double kStiffnessTolerance_N_per_m = 1.0;

// --- the supervisor (teleop.v1.Supervisor) ---------------------------------------------------

// A sustained oscillation larger than this many of the master's encoder counts is an alarm.
inline constexpr double kOscillationThreshold_counts = 2.0;
// Energy a side may generate (passivity observer) before an alarm ...
inline constexpr double kPassivityThreshold_J = 0.005;
// ... while it still gives out more than this mean power over the last second.
inline constexpr double kPassivityPowerThreshold_W = 0.002;
// An alarm persisting this long lowers the fixture stiffness; this long again, disengages.
inline constexpr std::chrono::milliseconds kEscalation{500};
// Ramp of every accepted parameter change.
inline constexpr std::chrono::milliseconds kChangeRamp{200};
// Session retention in the record directory: how many session files and how many MB are kept
// (the oldest removed when a new session starts); 0: no limit.
inline constexpr std::uint32_t kMaxSessions = 0;
inline constexpr double kMaxSessions_MB = 0.0;

// --- endpoints (loopback) --------------------------------------------------------------------

inline constexpr std::string_view kMasterStateEndpoint = "tcp://127.0.0.1:5560";
inline constexpr std::string_view kSlaveStateEndpoint = "tcp://127.0.0.1:5561";
inline constexpr std::string_view kMasterCommandEndpoint = "tcp://127.0.0.1:5562";
inline constexpr std::string_view kSlaveCommandEndpoint = "tcp://127.0.0.1:5563";
inline constexpr std::string_view kMasterTelemetryEndpoint = "tcp://127.0.0.1:5564";
inline constexpr std::string_view kSlaveTelemetryEndpoint = "tcp://127.0.0.1:5565";
inline constexpr std::string_view kSupervisorReportEndpoint = "tcp://127.0.0.1:5566";
inline constexpr std::string_view kSupervisorRequestEndpoint = "tcp://127.0.0.1:5567";
// `teleopctl replay --speed`'s control endpoint.
inline constexpr std::string_view kReplayControlEndpoint = "tcp://127.0.0.1:5568";

}  // namespace teleop::defaults
