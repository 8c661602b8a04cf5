// recover_file (mcap_reader.hpp): a damaged session's readable messages into a new file.
#include <chrono>
#include <map>
#include <stdexcept>

#include "common/record/mcap_reader.hpp"
#include "common/record/mcap_writer.hpp"

namespace teleop::record {

RecoveryReport recover_file(const std::filesystem::path& in, const std::filesystem::path& out,
                            const ByteProgress& scanned, const ByteProgress& written) {
  const McapReader reader = McapReader::recover(in, scanned);
  const std::uint64_t data_end = reader.recovery()->data_end;
  WriterOptions options{};
  options.profile = reader.header().profile;
  options.library = reader.header().library + "; recovered by teleop-record";
  // Offline: chunks by size only, so the output does not depend on how fast this runs.
  options.max_chunk_age = std::chrono::nanoseconds::max();
  McapWriter writer(out, options);
  std::map<std::uint16_t, std::uint16_t> schema_ids;
  for (const auto& [id, s] : reader.schemas()) {
    schema_ids[id] = writer.add_schema(SchemaDef{s.name, s.encoding, s.data});
  }
  std::map<std::uint16_t, std::uint16_t> channel_ids;
  for (const auto& [id, ch] : reader.channels()) {
    const auto schema = schema_ids.find(ch.schema_id);
    channel_ids[id] = writer.add_channel(
        ChannelDef{schema == schema_ids.end() ? std::uint16_t{0} : schema->second, ch.topic,
                   ch.message_encoding, ch.metadata});
  }
  reader.for_each_message(Order::kFile, [&](const MessageView& m) {
    if (!writer.write(channel_ids.at(m.channel->id), m.log_time_ns, m.publish_time_ns, m.sequence,
                      m.data)) {
      throw std::runtime_error(writer.error());
    }
    if (written) written(m.record_offset, data_end);
  });
  if (!writer.close()) throw std::runtime_error(writer.error());
  if (written) written(data_end, data_end);
  return *reader.recovery();
}

}  // namespace teleop::record
