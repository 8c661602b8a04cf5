#include "common/record/proto_schema.hpp"

#include <google/protobuf/descriptor.pb.h>

#include <set>
#include <stdexcept>

namespace teleop::record {

namespace {

// Post-order over imports: every file lands after the files it imports.
void add_file(const google::protobuf::FileDescriptor* file,
              std::set<const google::protobuf::FileDescriptor*>& seen,
              google::protobuf::FileDescriptorSet& set) {
  if (!seen.insert(file).second) return;
  for (int i = 0; i < file->dependency_count(); ++i) add_file(file->dependency(i), seen, set);
  file->CopyTo(set.add_file());
}

}  // namespace

std::string file_descriptor_set(const google::protobuf::Descriptor* descriptor) {
  if (descriptor == nullptr) throw std::invalid_argument("file_descriptor_set: null descriptor");
  google::protobuf::FileDescriptorSet set;
  std::set<const google::protobuf::FileDescriptor*> seen;
  add_file(descriptor->file(), seen, set);
  return set.SerializeAsString();
}

SchemaDef protobuf_schema(const google::protobuf::Descriptor* descriptor) {
  std::string data = file_descriptor_set(descriptor);  // throws for a null descriptor
  return SchemaDef{descriptor->full_name(), "protobuf", std::move(data)};
}

ChannelDef protobuf_channel(std::uint16_t schema_id, std::string topic,
                            std::map<std::string, std::string> metadata) {
  return ChannelDef{schema_id, std::move(topic), "protobuf", std::move(metadata)};
}

}  // namespace teleop::record
