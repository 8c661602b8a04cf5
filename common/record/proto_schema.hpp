// Protobuf schemas for MCAP channels (the spec's registry: schema encoding "protobuf", name =
// the message's full name, data = a FileDescriptorSet holding the message's file and every
// file it imports, each after its imports, as `protoc --include_imports` writes it).
#pragma once

#include <google/protobuf/descriptor.h>

#include <map>
#include <string>

#include "common/record/mcap_writer.hpp"

namespace teleop::record {

// Serialized google.protobuf.FileDescriptorSet for `descriptor`, dependencies first.
[[nodiscard]] std::string file_descriptor_set(const google::protobuf::Descriptor* descriptor);

// The Schema record for messages of `descriptor`.
[[nodiscard]] SchemaDef protobuf_schema(const google::protobuf::Descriptor* descriptor);

// A channel carrying protobuf messages of an already added schema.
[[nodiscard]] ChannelDef protobuf_channel(std::uint16_t schema_id, std::string topic,
                                          std::map<std::string, std::string> metadata = {});

}  // namespace teleop::record
