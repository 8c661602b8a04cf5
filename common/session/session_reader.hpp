// A recorded session read back (issue 5 "Replay and identification"): the MCAP file the
// supervisor or `teleopctl simulate --out` writes (one channel per topic of session.hpp, each
// carrying protobuf messages), as typed values with their log times: the configuration, each
// node's telemetry and the cycles it recorded, the supervisor's stability reports, alarms,
// parameter changes and status. Tool code (teleopctl replay and identify, tests): allocates and
// throws std::runtime_error naming the file.
#pragma once

#include <google/protobuf/descriptor.h>
#include <google/protobuf/dynamic_message.h>
#include <google/protobuf/message.h>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/node/node_core.hpp"
#include "common/node/node_core_axes.hpp"
#include "common/record/mcap_reader.hpp"
#include "common/record/session.hpp"
#include "teleop/v1/config.pb.h"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::record {

// A message of a session with its log time (ns, on the recorder's clock).
template <typename T>
struct Stamped {
  std::uint64_t log_time_ns{0};
  T message{};
};

// One control cycle as a node recorded it: the node's own record type (node_core.hpp), decoded
// from teleop.v1.CycleRecord by the one decoder (common/telemetry/cycle_codec.hpp), with the
// session of the Telemetry message that carried it. The record's `reason` is not recorded per cycle
// (""); a mode this version does not know (or none) reads as disarmed.
struct RecordedCycle {
  std::uint64_t session_id{0};
  node::CycleRecord cycle{};
};

// One control cycle of n task-space axes (issue 18): teleop.v1.CycleRecord decoded by
// telemetry::axes_from_proto, a one-axis record as axis 0 of a 1-axis record. Per axis:
// cycle.position_m[i] etc. for i < cycle.axes.
struct RecordedCycleAxes {
  std::uint64_t session_id{0};
  node::CycleRecordAxes cycle{};
};

// What one pass over a session hands out, in log-time order; a callback left empty skips its
// topic (its messages are then not decoded). `message` sees every message first, typed or not.
struct SessionVisitor {
  std::function<void(const MessageView&)> message{};
  std::function<void(std::uint64_t log_time_ns, bool master, const v1::Telemetry&)> telemetry{};
  std::function<void(std::uint64_t log_time_ns, const v1::StabilityReport&)> report{};
  std::function<void(std::uint64_t log_time_ns, const v1::Alarm&)> alarm{};
  std::function<void(std::uint64_t log_time_ns, const v1::ParameterChangeRecord&)>
      parameter_change{};
  std::function<void(std::uint64_t log_time_ns, const v1::SupervisorStatus&)> status{};
};

class SessionReader {
 public:
  // Throws std::runtime_error naming the file: no such file, not MCAP, or damaged or cut short
  // (then the message says that `teleopctl replay --recover OUT.mcap FILE` keeps every complete
  // chunk).
  [[nodiscard]] static SessionReader open(const std::filesystem::path& path);

  // The file underneath (channels, schemas, statistics, raw messages).
  [[nodiscard]] const McapReader& mcap() const { return reader_; }
  // The file's path as given to open().
  [[nodiscard]] std::string path() const { return reader_.path().string(); }
  [[nodiscard]] bool has_topic(std::string_view topic) const;
  // The topics of every channel, "a, b, c" in channel-id order ("none" when there is none).
  [[nodiscard]] std::string channel_list() const;
  // Log time of the first and of the last message, ns (0 when there is none).
  [[nodiscard]] std::uint64_t first_log_time_ns() const;
  [[nodiscard]] std::uint64_t last_log_time_ns() const;

  // Every message of `topic`, in log-time order; empty when there is no such channel.
  [[nodiscard]] std::vector<MessageView> messages_on(std::string_view topic) const;
  // `m` as a T. Throws naming the file: its channel carries another type, or it does not decode.
  template <typename T>
  [[nodiscard]] T decode(const MessageView& m) const {
    T t;
    decode_into(m, t);
    return t;
  }

  // One pass over every message (see SessionVisitor); throws as decode() does.
  void visit(const SessionVisitor& visitor) const;
  // Every Telemetry message one node published, in log-time order (none without the channel).
  // `read`: how far the pass is through the file (the offset of the chunk being read, of the
  // file's size; the size at the end).
  void for_each_telemetry(bool master,
                          const std::function<void(std::uint64_t, const v1::Telemetry&)>& fn,
                          const ByteProgress& read = {}) const;

  // The configuration (the newest message on /config); nullopt without the channel. `read` as
  // for for_each_telemetry (a pass over the whole file).
  [[nodiscard]] std::optional<v1::SystemConfig> config(const ByteProgress& read = {}) const;
  // Every cycle one node recorded (the CycleRecords of its telemetry, in log-time order; flight
  // records, which repeat cycles, left out). Throws naming the file when there is no such
  // channel ("FILE: no channel '/slave/telemetry' (channels: ...)"). `read` as for
  // for_each_telemetry.
  // A cycle of several axes has no one-axis form: it throws naming the file, topic and sequence
  // (read such sessions with cycles_axes()), as does a record the codec refuses.
  [[nodiscard]] std::vector<RecordedCycle> cycles(bool master, const ByteProgress& read = {}) const;
  // Every cycle one node recorded, of any number of axes (a one-axis session as 1-axis cycles).
  // Throws as cycles() for a missing channel, and for a record the codec refuses (more than
  // kMaxAxes axes, or a per-axis field not holding `axes` entries): "FILE: /master/telemetry
  // cycle 12 (log time T ns): ...".
  [[nodiscard]] std::vector<RecordedCycleAxes> cycles_axes(bool master,
                                                           const ByteProgress& read = {}) const;
  [[nodiscard]] std::vector<Stamped<v1::StabilityReport>> reports() const;
  [[nodiscard]] std::vector<Stamped<v1::Alarm>> alarms() const;
  [[nodiscard]] std::vector<Stamped<v1::ParameterChangeRecord>> parameter_changes() const;
  [[nodiscard]] std::vector<Stamped<v1::SupervisorStatus>> statuses() const;

 private:
  explicit SessionReader(McapReader reader) : reader_(std::move(reader)) {}
  // Every message of `topic` in log-time order to `fn`, `read` following the pass.
  void for_each_on(std::string_view topic, const std::function<void(const MessageView&)>& fn,
                   const ByteProgress& read) const;
  void decode_into(const MessageView& m, google::protobuf::Message& out) const;

  McapReader reader_;
};

// The recorded configuration with `overrides` (`--set PATH=VALUE`) applied and validated
// (config_loader.hpp; messages name "FILE (/config)"); nullopt when the session has no /config,
// which throws instead when there are overrides to apply. `read` as for SessionReader::config.
[[nodiscard]] std::optional<config::LoadedConfig> recorded_config(
    const SessionReader& session, const std::vector<std::string>& overrides = {},
    const ByteProgress& read = {});

// The recorder's drop count a supervisor message carries (the uint64 field recording_drops of
// its type, found by reflection); nullopt when its type has none or it does not decode.
[[nodiscard]] std::optional<std::uint64_t> recording_drops(const MessageView& m);

// Whether `path` starts with the MCAP magic (false when it cannot be read).
[[nodiscard]] bool is_mcap_file(const std::filesystem::path& path);

// Messages of one schema decoded through the FileDescriptorSet the file embeds, so files of
// other versions decode too. Throws std::runtime_error naming the schema: not protobuf, its
// descriptors do not parse or build, or they lack the message.
class EmbeddedSchemaDecoder {
 public:
  explicit EmbeddedSchemaDecoder(const Schema& schema);
  // nullptr when `data` does not decode.
  [[nodiscard]] std::unique_ptr<google::protobuf::Message> decode(std::string_view data) const;

 private:
  google::protobuf::DescriptorPool pool_{};
  google::protobuf::DynamicMessageFactory factory_{&pool_};
  const google::protobuf::Message* prototype_{nullptr};
};

}  // namespace teleop::record
