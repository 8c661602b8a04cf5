#include "common/session/session_reader.hpp"

#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/text_format.h>

#include <algorithm>
#include <fstream>
#include <stdexcept>
#include <utility>

#include "common/telemetry/cycle_codec.hpp"

namespace teleop::record {
namespace {

namespace pb = google::protobuf;

template <typename T>
std::vector<Stamped<T>> stamped_on(const SessionReader& session, std::string_view topic) {
  std::vector<Stamped<T>> out;
  for (const MessageView& m : session.messages_on(topic)) {
    out.push_back({m.log_time_ns, session.decode<T>(m)});
  }
  return out;
}

// "FILE: /master/telemetry cycle 12 (log time T ns): " for a record's errors.
std::string cycle_at(const SessionReader& session, std::string_view topic,
                     std::uint64_t log_time_ns, const v1::CycleRecord& c) {
  return session.path() + ": " + std::string(topic) + " cycle " + std::to_string(c.sequence()) +
         " (log time " + std::to_string(log_time_ns) + " ns): ";
}

// The record as n axes, or an error naming where it is.
node::CycleRecordAxes axes_or_throw(const SessionReader& session, std::string_view topic,
                                    std::uint64_t log_time_ns, const v1::CycleRecord& c) {
  const std::optional<node::CycleRecordAxes> r = telemetry::axes_from_proto(c);
  if (!r) {
    throw std::runtime_error(cycle_at(session, topic, log_time_ns, c) + "a record of " +
                             std::to_string(c.axes()) + " axes the codec refuses (at most " +
                             std::to_string(kMaxAxes) +
                             " axes, each per-axis field holding one entry per axis; positions " +
                             std::to_string(c.positions_m_size()) + ", forces " +
                             std::to_string(c.forces_n_size()) + ")");
  }
  return *r;
}

}  // namespace

SessionReader SessionReader::open(const std::filesystem::path& path) {
  if (!std::filesystem::exists(path)) {
    throw std::runtime_error(path.string() + ": no such file");
  }
  try {
    return SessionReader(McapReader::open(path));
  } catch (const McapError& e) {
    if (!is_mcap_file(path)) throw;
    throw std::runtime_error(
        std::string(e.what()) +
        "\n(the file was cut short or damaged: 'teleopctl replay --recover OUT.mcap " +
        path.string() + "' keeps every complete chunk)");
  }
}

bool SessionReader::has_topic(std::string_view topic) const {
  for (const auto& [id, ch] : reader_.channels()) {
    if (ch.topic == topic) return true;
  }
  return false;
}

std::string SessionReader::channel_list() const {
  std::string s;
  for (const auto& [id, ch] : reader_.channels()) s += (s.empty() ? "" : ", ") + ch.topic;
  return s.empty() ? "none" : s;
}

std::uint64_t SessionReader::first_log_time_ns() const {
  if (reader_.statistics() && reader_.statistics()->message_count > 0) {
    return reader_.statistics()->message_start_time;
  }
  std::uint64_t t = UINT64_MAX;
  reader_.for_each_message(Order::kFile,
                           [&](const MessageView& m) { t = std::min(t, m.log_time_ns); });
  return t == UINT64_MAX ? 0 : t;
}

std::uint64_t SessionReader::last_log_time_ns() const {
  if (reader_.statistics() && reader_.statistics()->message_count > 0) {
    return reader_.statistics()->message_end_time;
  }
  std::uint64_t t = 0;
  reader_.for_each_message(Order::kFile,
                           [&](const MessageView& m) { t = std::max(t, m.log_time_ns); });
  return t;
}

std::vector<MessageView> SessionReader::messages_on(std::string_view topic) const {
  std::vector<MessageView> out;
  reader_.for_each_message(Order::kLogTime, [&](const MessageView& m) {
    if (m.channel->topic == topic) out.push_back(m);
  });
  return out;
}

void SessionReader::decode_into(const MessageView& m, pb::Message& out) const {
  const std::string& want = out.GetDescriptor()->full_name();
  if (m.schema == nullptr || m.schema->name != want) {
    throw std::runtime_error(path() + ": channel " + m.channel->topic + " carries " +
                             (m.schema ? m.schema->name : "no schema") + ", not " + want);
  }
  if (!out.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) {
    throw std::runtime_error(path() + ": " + m.channel->topic + " message at log time " +
                             std::to_string(m.log_time_ns) + " ns does not decode as " + want);
  }
}

void SessionReader::visit(const SessionVisitor& v) const {
  reader_.for_each_message(Order::kLogTime, [&](const MessageView& m) {
    if (v.message) v.message(m);
    const std::string& topic = m.channel->topic;
    if ((topic == topic::kMasterTelemetry || topic == topic::kSlaveTelemetry) && v.telemetry) {
      v.telemetry(m.log_time_ns, topic == topic::kMasterTelemetry, decode<v1::Telemetry>(m));
    } else if (topic == topic::kAlarms && v.alarm) {
      v.alarm(m.log_time_ns, decode<v1::Alarm>(m));
    } else if (topic == topic::kParameterChanges && v.parameter_change) {
      v.parameter_change(m.log_time_ns, decode<v1::ParameterChangeRecord>(m));
    } else if (topic == topic::kStability && v.report) {
      v.report(m.log_time_ns, decode<v1::StabilityReport>(m));
    } else if (topic == topic::kStatus && v.status) {
      v.status(m.log_time_ns, decode<v1::SupervisorStatus>(m));
    }
  });
}

void SessionReader::for_each_on(std::string_view topic,
                                const std::function<void(const MessageView&)>& fn,
                                const ByteProgress& read) const {
  const std::uint64_t size = reader_.file_size();
  std::uint64_t done = 0;
  reader_.for_each_message(Order::kLogTime, [&](const MessageView& m) {
    if (read && m.record_offset > done) {
      done = m.record_offset;
      read(done, size);
    }
    if (m.channel->topic == topic) fn(m);
  });
  if (read) read(size, size);
}

void SessionReader::for_each_telemetry(
    bool master, const std::function<void(std::uint64_t, const v1::Telemetry&)>& fn,
    const ByteProgress& read) const {
  // Decoded as the pass reaches them: the file is read once, and `read` follows it.
  for_each_on(
      topic::telemetry(master),
      [&](const MessageView& m) { fn(m.log_time_ns, decode<v1::Telemetry>(m)); }, read);
}

std::optional<v1::SystemConfig> SessionReader::config(const ByteProgress& read) const {
  std::optional<MessageView> newest;
  for_each_on(
      topic::kConfig, [&](const MessageView& m) { newest = m; }, read);
  if (!newest) return std::nullopt;
  return decode<v1::SystemConfig>(*newest);
}

std::vector<RecordedCycle> SessionReader::cycles(bool master, const ByteProgress& read) const {
  const std::string_view topic = topic::telemetry(master);
  if (!has_topic(topic)) {
    throw std::runtime_error(path() + ": no channel '" + std::string(topic) +
                             "' (channels: " + channel_list() + ")");
  }
  std::vector<RecordedCycle> cycles;
  for_each_telemetry(
      master,
      [&](std::uint64_t log_time_ns, const v1::Telemetry& t) {
        for (const v1::CycleRecord& c : t.cycles()) {
          const node::CycleRecordAxes n = axes_or_throw(*this, topic, log_time_ns, c);
          if (n.axes != 1) {
            throw std::runtime_error(cycle_at(*this, topic, log_time_ns, c) + "a record of " +
                                     std::to_string(n.axes) +
                                     " axes, read one axis (read it as n axes)");
          }
          cycles.push_back({t.session_id(), telemetry::from_proto(c)});
        }
      },
      read);
  return cycles;
}

std::vector<RecordedCycleAxes> SessionReader::cycles_axes(bool master,
                                                          const ByteProgress& read) const {
  const std::string_view topic = topic::telemetry(master);
  if (!has_topic(topic)) {
    throw std::runtime_error(path() + ": no channel '" + std::string(topic) +
                             "' (channels: " + channel_list() + ")");
  }
  std::vector<RecordedCycleAxes> cycles;
  for_each_telemetry(
      master,
      [&](std::uint64_t log_time_ns, const v1::Telemetry& t) {
        for (const v1::CycleRecord& c : t.cycles()) {
          cycles.push_back({t.session_id(), axes_or_throw(*this, topic, log_time_ns, c)});
        }
      },
      read);
  return cycles;
}

std::vector<Stamped<v1::StabilityReport>> SessionReader::reports() const {
  return stamped_on<v1::StabilityReport>(*this, topic::kStability);
}

std::vector<Stamped<v1::Alarm>> SessionReader::alarms() const {
  return stamped_on<v1::Alarm>(*this, topic::kAlarms);
}

std::vector<Stamped<v1::ParameterChangeRecord>> SessionReader::parameter_changes() const {
  return stamped_on<v1::ParameterChangeRecord>(*this, topic::kParameterChanges);
}

std::vector<Stamped<v1::SupervisorStatus>> SessionReader::statuses() const {
  return stamped_on<v1::SupervisorStatus>(*this, topic::kStatus);
}

std::optional<config::LoadedConfig> recorded_config(const SessionReader& session,
                                                    const std::vector<std::string>& overrides,
                                                    const ByteProgress& read) {
  const std::optional<v1::SystemConfig> recorded = session.config(read);
  if (!recorded) {
    if (!overrides.empty()) {
      throw std::runtime_error(session.path() + ": no /config channel to apply --set to");
    }
    return std::nullopt;
  }
  std::string text;
  pb::TextFormat::PrintToString(*recorded, &text);
  return config::load_config_text(text, session.path() + " (/config)", overrides);
}

std::optional<std::uint64_t> recording_drops(const MessageView& m) {
  if (m.schema == nullptr) return std::nullopt;
  const pb::Descriptor* d =
      pb::DescriptorPool::generated_pool()->FindMessageTypeByName(m.schema->name);
  const pb::FieldDescriptor* f = d ? d->FindFieldByName("recording_drops") : nullptr;
  if (f == nullptr || f->cpp_type() != pb::FieldDescriptor::CPPTYPE_UINT64) return std::nullopt;
  std::unique_ptr<pb::Message> msg(pb::MessageFactory::generated_factory()->GetPrototype(d)->New());
  if (!msg->ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) return std::nullopt;
  return msg->GetReflection()->GetUInt64(*msg, f);
}

bool is_mcap_file(const std::filesystem::path& path) {
  std::ifstream f(path, std::ios::binary);
  char magic[8] = {};
  f.read(magic, sizeof magic);
  return f.gcount() == 8 && std::string_view(magic, 8) == std::string_view("\x89MCAP0\r\n", 8);
}

EmbeddedSchemaDecoder::EmbeddedSchemaDecoder(const Schema& schema) {
  if (schema.encoding != "protobuf") {
    throw std::runtime_error("schema '" + schema.name + "' has encoding '" + schema.encoding +
                             "', not protobuf");
  }
  pb::FileDescriptorSet set;
  if (!set.ParseFromString(schema.data)) {
    throw std::runtime_error("schema '" + schema.name + "': its FileDescriptorSet does not parse");
  }
  for (const pb::FileDescriptorProto& f : set.file()) {
    if (pool_.BuildFile(f) == nullptr) {
      throw std::runtime_error("schema '" + schema.name + "': file " + f.name() +
                               " does not build");
    }
  }
  const pb::Descriptor* d = pool_.FindMessageTypeByName(schema.name);
  if (d == nullptr) {
    throw std::runtime_error("schema '" + schema.name + "': no such message in its descriptors");
  }
  prototype_ = factory_.GetPrototype(d);
}

std::unique_ptr<pb::Message> EmbeddedSchemaDecoder::decode(std::string_view data) const {
  std::unique_ptr<pb::Message> m(prototype_->New());
  if (!m->ParseFromArray(data.data(), static_cast<int>(data.size()))) return nullptr;
  return m;
}

}  // namespace teleop::record
