#include "python/session_columns.hpp"

#include <google/protobuf/message.h>

#include <memory>
#include <stdexcept>

namespace teleop::python {

namespace {

namespace pb = google::protobuf;
using FD = pb::FieldDescriptor;

// Nested messages deeper than this are not flattened (a recursive type would never end).
constexpr int kMaxDepth = 4;

bool leaf_kind(const FD& f, Column::Kind& kind) {
  switch (f.cpp_type()) {
    case FD::CPPTYPE_DOUBLE:
    case FD::CPPTYPE_FLOAT:
      kind = Column::Kind::kDouble;
      return true;
    case FD::CPPTYPE_INT32:
    case FD::CPPTYPE_INT64:
      kind = Column::Kind::kSigned;
      return true;
    case FD::CPPTYPE_UINT32:
    case FD::CPPTYPE_UINT64:
      kind = Column::Kind::kUnsigned;
      return true;
    case FD::CPPTYPE_BOOL:
      kind = Column::Kind::kBool;
      return true;
    case FD::CPPTYPE_ENUM:
      kind = Column::Kind::kEnum;
      return true;
    case FD::CPPTYPE_STRING:
      kind = Column::Kind::kString;
      return f.type() == FD::TYPE_STRING;  // bytes: no column
    case FD::CPPTYPE_MESSAGE:
      return false;
  }
  return false;
}

void add_columns(const pb::Descriptor& d, std::vector<const FD*>& path, const std::string& prefix,
                 std::vector<Column>& out) {
  for (int i = 0; i < d.field_count(); ++i) {
    const FD* f = d.field(i);
    if (f->is_repeated()) continue;
    const std::string name = prefix + f->name();
    if (f->cpp_type() == FD::CPPTYPE_MESSAGE) {
      if (static_cast<int>(path.size()) + 1 >= kMaxDepth) continue;
      path.push_back(f);
      add_columns(*f->message_type(), path, name + ".", out);
      path.pop_back();
      continue;
    }
    Column c;
    if (!leaf_kind(*f, c.kind)) continue;
    c.name = name;
    c.path = path;
    c.leaf = f;
    if (c.kind == Column::Kind::kEnum) {
      const pb::EnumDescriptor* e = f->enum_type();
      for (int v = 0; v < e->value_count(); ++v) {
        c.enum_names.emplace(e->value(v)->number(), e->value(v)->name());
      }
    }
    out.push_back(std::move(c));
  }
}

void append(Column& c, const pb::Message& top) {
  const pb::Message* m = &top;
  for (const FD* f : c.path) m = &m->GetReflection()->GetMessage(*m, f);
  const pb::Reflection& r = *m->GetReflection();
  const FD* f = c.leaf;
  switch (c.kind) {
    case Column::Kind::kDouble:
      c.doubles.push_back(f->cpp_type() == FD::CPPTYPE_FLOAT ? r.GetFloat(*m, f)
                                                             : r.GetDouble(*m, f));
      break;
    case Column::Kind::kSigned:
      c.signed_values.push_back(f->cpp_type() == FD::CPPTYPE_INT32 ? r.GetInt32(*m, f)
                                                                   : r.GetInt64(*m, f));
      break;
    case Column::Kind::kUnsigned:
      c.unsigned_values.push_back(f->cpp_type() == FD::CPPTYPE_UINT32 ? r.GetUInt32(*m, f)
                                                                      : r.GetUInt64(*m, f));
      break;
    case Column::Kind::kBool:
      c.signed_values.push_back(r.GetBool(*m, f) ? 1 : 0);
      break;
    case Column::Kind::kEnum:
      c.signed_values.push_back(r.GetEnumValue(*m, f));
      break;
    case Column::Kind::kString:
      c.strings.push_back(r.GetString(*m, f));
      break;
  }
}

}  // namespace

std::vector<ChannelColumns> read_channel_columns(const record::SessionReader& session) {
  const record::McapReader& mcap = session.mcap();
  std::map<std::uint16_t, std::unique_ptr<record::EmbeddedSchemaDecoder>> decoders;
  std::map<std::uint16_t, ChannelColumns> channels;  // by channel id
  mcap.for_each_message(record::Order::kLogTime, [&](const record::MessageView& v) {
    if (v.schema == nullptr || v.schema->encoding != "protobuf") return;
    auto dec = decoders.find(v.schema->id);
    if (dec == decoders.end()) {
      dec =
          decoders.emplace(v.schema->id, std::make_unique<record::EmbeddedSchemaDecoder>(*v.schema))
              .first;
    }
    const std::unique_ptr<pb::Message> m = dec->second->decode(v.data);
    if (!m) {
      throw std::runtime_error(session.path() + ": " + v.channel->topic + " message at log time " +
                               std::to_string(v.log_time_ns) + " ns does not decode as " +
                               v.schema->name);
    }
    auto [it, fresh] = channels.try_emplace(v.channel->id);
    ChannelColumns& ch = it->second;
    if (fresh) {
      ch.topic = v.channel->topic;
      ch.schema = v.schema->name;
      std::vector<const FD*> path;
      add_columns(*m->GetDescriptor(), path, "", ch.columns);
    }
    ch.log_time_ns.push_back(v.log_time_ns);
    ch.publish_time_ns.push_back(v.publish_time_ns);
    for (Column& c : ch.columns) append(c, *m);
  });
  std::map<std::string, ChannelColumns> by_topic;
  for (auto& [id, ch] : channels) by_topic.emplace(ch.topic, std::move(ch));
  std::vector<ChannelColumns> out;
  for (auto& [topic, ch] : by_topic) out.push_back(std::move(ch));
  return out;
}

}  // namespace teleop::python
