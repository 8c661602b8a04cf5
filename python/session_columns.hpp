// A recorded session as columns: every message of one channel decoded through the schema the
// file embeds (so sessions of other versions read too), each scalar field (nested messages
// flattened as "loop.period_s") one column with a value per message. Plain C++ (no Python), so
// the module can read a session with the interpreter's lock released.
#pragma once

#include <google/protobuf/descriptor.h>

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "common/session/session_reader.hpp"

namespace teleop::python {

// One field of a channel, a value per message. Which vector holds the values follows `kind`.
struct Column {
  enum class Kind { kDouble, kSigned, kUnsigned, kBool, kEnum, kString };
  std::string name{};  // the proto field names from the message down, joined by '.'
  Kind kind{Kind::kDouble};
  // The message fields leading to the leaf (empty for a top-level field), then the leaf.
  std::vector<const google::protobuf::FieldDescriptor*> path{};
  const google::protobuf::FieldDescriptor* leaf{nullptr};
  std::vector<double> doubles{};
  std::vector<std::int64_t> signed_values{};  // kSigned, kEnum (the number), kBool (0 or 1)
  std::vector<std::uint64_t> unsigned_values{};
  std::vector<std::string> strings{};
  std::map<int, std::string> enum_names{};  // kEnum: number -> name
};

// One channel: the MCAP times of its messages and a column per scalar field.
struct ChannelColumns {
  std::string topic{};
  std::string schema{};  // the message type's full name
  std::vector<std::uint64_t> log_time_ns{};
  std::vector<std::uint64_t> publish_time_ns{};
  std::vector<Column> columns{};
};

// Every channel with a protobuf schema, in topic order. Repeated fields (Telemetry's batched
// cycles: the per-cycle channels carry them one by one) and bytes are not columns. Throws
// std::runtime_error naming the file and topic when a message does not decode.
[[nodiscard]] std::vector<ChannelColumns> read_channel_columns(
    const record::SessionReader& session);

}  // namespace teleop::python
