// `--set PATH=VALUE` overrides and the fields a message sets (text_format.hpp): the generic
// half of config_loader.hpp's apply_override, set_fields and the check of paths given twice.
#include <google/protobuf/message.h>

#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>
#include <utility>
#include <variant>

#include "common/config/text_format.hpp"

namespace teleop::config::text_format {
namespace {

namespace pb = google::protobuf;

// ---------------------------------------------------------------------------------------------
// Overrides

using ScalarValue = std::variant<double, float, std::int32_t, std::int64_t, std::uint32_t,
                                 std::uint64_t, bool, const pb::EnumValueDescriptor*, std::string>;

// from_chars rejects the leading '+' that people (and strtod) accept.
std::string_view without_plus(std::string_view text) {
  return text.size() > 1 && text.front() == '+' && text[1] != '-' ? text.substr(1) : text;
}

// The whole of `text` (a leading '+' allowed) as a Number; otherwise nullopt and `why`: "out of
// range", or `not_one` when it is not a Number at all.
template <typename Number>
std::optional<Number> parse_whole(std::string_view text, std::string& why, const char* not_one) {
  text = without_plus(text);
  Number value{};
  const auto result = std::from_chars(text.data(), text.data() + text.size(), value);
  if (result.ec == std::errc::result_out_of_range) {
    why = "out of range";
    return std::nullopt;
  }
  if (result.ec != std::errc{} || result.ptr != text.data() + text.size()) {
    why = not_one;
    return std::nullopt;
  }
  return value;
}

template <typename Integer>
std::optional<Integer> parse_integer(std::string_view text, std::string& why) {
  return parse_whole<Integer>(text, why, "not an integer");
}

std::optional<double> parse_double(std::string_view text, std::string& why) {
  return parse_whole<double>(text, why, "not a number");
}

// Parses one scalar for `field`; on failure returns nullopt and says why.
std::optional<ScalarValue> parse_scalar(const pb::FieldDescriptor* field, std::string_view text,
                                        std::string& why) {
  using F = pb::FieldDescriptor;
  if (text.empty() && field->cpp_type() != F::CPPTYPE_STRING) {
    why = "empty value";
    return std::nullopt;
  }
  switch (field->cpp_type()) {
    case F::CPPTYPE_DOUBLE:
      if (const auto value = parse_double(text, why)) return ScalarValue{*value};
      return std::nullopt;
    case F::CPPTYPE_FLOAT:
      if (const auto value = parse_double(text, why)) {
        if (std::isfinite(*value) && std::abs(*value) > std::numeric_limits<float>::max()) {
          why = "out of range";
          return std::nullopt;
        }
        return ScalarValue{static_cast<float>(*value)};
      }
      return std::nullopt;
    case F::CPPTYPE_INT32:
      if (const auto value = parse_integer<std::int32_t>(text, why)) return ScalarValue{*value};
      return std::nullopt;
    case F::CPPTYPE_INT64:
      if (const auto value = parse_integer<std::int64_t>(text, why)) return ScalarValue{*value};
      return std::nullopt;
    case F::CPPTYPE_UINT32:
      if (const auto value = parse_integer<std::uint32_t>(text, why)) return ScalarValue{*value};
      return std::nullopt;
    case F::CPPTYPE_UINT64:
      if (const auto value = parse_integer<std::uint64_t>(text, why)) return ScalarValue{*value};
      return std::nullopt;
    case F::CPPTYPE_BOOL:
      if (text == "true" || text == "1") return ScalarValue{true};
      if (text == "false" || text == "0") return ScalarValue{false};
      why = "not a bool (true, false, 1 or 0)";
      return std::nullopt;
    case F::CPPTYPE_ENUM: {
      const pb::EnumDescriptor* type = field->enum_type();
      if (const auto* value = type->FindValueByName(std::string(text))) return ScalarValue{value};
      why = "not a value of " + type->full_name() + " (one of:";
      for (int i = 0; i < type->value_count(); ++i) why += " " + type->value(i)->name();
      why += ")";
      return std::nullopt;
    }
    case F::CPPTYPE_STRING:
      return ScalarValue{std::string(text)};
    case F::CPPTYPE_MESSAGE:
      break;
  }
  why = "not a scalar";
  return std::nullopt;
}

template <typename... Ts>
struct Overloaded : Ts... {
  using Ts::operator()...;
};
template <typename... Ts>
Overloaded(Ts...) -> Overloaded<Ts...>;

void set_scalar(pb::Message& message, const pb::FieldDescriptor* field, const ScalarValue& value) {
  const pb::Reflection* r = message.GetReflection();
  const bool add = field->is_repeated();
  std::visit(
      Overloaded{
          [&](double v) {
            add ? r->AddDouble(&message, field, v) : r->SetDouble(&message, field, v);
          },
          [&](float v) { add ? r->AddFloat(&message, field, v) : r->SetFloat(&message, field, v); },
          [&](std::int32_t v) {
            add ? r->AddInt32(&message, field, v) : r->SetInt32(&message, field, v);
          },
          [&](std::int64_t v) {
            add ? r->AddInt64(&message, field, v) : r->SetInt64(&message, field, v);
          },
          [&](std::uint32_t v) {
            add ? r->AddUInt32(&message, field, v) : r->SetUInt32(&message, field, v);
          },
          [&](std::uint64_t v) {
            add ? r->AddUInt64(&message, field, v) : r->SetUInt64(&message, field, v);
          },
          [&](bool v) { add ? r->AddBool(&message, field, v) : r->SetBool(&message, field, v); },
          [&](const pb::EnumValueDescriptor* v) {
            add ? r->AddEnum(&message, field, v) : r->SetEnum(&message, field, v);
          },
          [&](const std::string& v) {
            add ? r->AddString(&message, field, v) : r->SetString(&message, field, v);
          },
      },
      value);
}

// Replaces element `index` of a repeated scalar.
void set_element(pb::Message& message, const pb::FieldDescriptor* field, int index,
                 const ScalarValue& value) {
  const pb::Reflection* r = message.GetReflection();
  std::visit(
      Overloaded{
          [&](double v) { r->SetRepeatedDouble(&message, field, index, v); },
          [&](float v) { r->SetRepeatedFloat(&message, field, index, v); },
          [&](std::int32_t v) { r->SetRepeatedInt32(&message, field, index, v); },
          [&](std::int64_t v) { r->SetRepeatedInt64(&message, field, index, v); },
          [&](std::uint32_t v) { r->SetRepeatedUInt32(&message, field, index, v); },
          [&](std::uint64_t v) { r->SetRepeatedUInt64(&message, field, index, v); },
          [&](bool v) { r->SetRepeatedBool(&message, field, index, v); },
          [&](const pb::EnumValueDescriptor* v) { r->SetRepeatedEnum(&message, field, index, v); },
          [&](const std::string& v) { r->SetRepeatedString(&message, field, index, v); },
      },
      value);
}

void collect_set_fields(const pb::Message& message, const std::string& prefix,
                        std::vector<FieldAssignment>& out) {
  const pb::Reflection* r = message.GetReflection();
  std::vector<const pb::FieldDescriptor*> fields;
  r->ListFields(message, &fields);
  if (fields.empty() && !prefix.empty()) out.push_back({prefix, "{}"});
  for (const pb::FieldDescriptor* field : fields) {
    const std::string path = prefix.empty() ? field->name() : prefix + "." + field->name();
    const int count = field->is_repeated() ? r->FieldSize(message, field) : 1;
    if (field->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE) {
      for (int i = 0; i < count; ++i) {
        if (field->is_repeated()) {
          collect_set_fields(r->GetRepeatedMessage(message, field, i),
                             path + "[" + std::to_string(i) + "]", out);
        } else {
          collect_set_fields(r->GetMessage(message, field), path, out);
        }
      }
      continue;
    }
    std::string value;
    for (int i = 0; i < count; ++i) {
      if (i > 0) value += ',';
      const int index = field->is_repeated() ? i : -1;
      switch (field->cpp_type()) {
        case pb::FieldDescriptor::CPPTYPE_DOUBLE:
          value += format_float(index < 0 ? r->GetDouble(message, field)
                                          : r->GetRepeatedDouble(message, field, index));
          break;
        case pb::FieldDescriptor::CPPTYPE_FLOAT:
          value += format_float(index < 0 ? r->GetFloat(message, field)
                                          : r->GetRepeatedFloat(message, field, index));
          break;
        case pb::FieldDescriptor::CPPTYPE_INT32:
          value += std::to_string(index < 0 ? r->GetInt32(message, field)
                                            : r->GetRepeatedInt32(message, field, index));
          break;
        case pb::FieldDescriptor::CPPTYPE_INT64:
          value += std::to_string(index < 0 ? r->GetInt64(message, field)
                                            : r->GetRepeatedInt64(message, field, index));
          break;
        case pb::FieldDescriptor::CPPTYPE_UINT32:
          value += std::to_string(index < 0 ? r->GetUInt32(message, field)
                                            : r->GetRepeatedUInt32(message, field, index));
          break;
        case pb::FieldDescriptor::CPPTYPE_UINT64:
          value += std::to_string(index < 0 ? r->GetUInt64(message, field)
                                            : r->GetRepeatedUInt64(message, field, index));
          break;
        case pb::FieldDescriptor::CPPTYPE_BOOL:
          value +=
              (index < 0 ? r->GetBool(message, field) : r->GetRepeatedBool(message, field, index))
                  ? "true"
                  : "false";
          break;
        case pb::FieldDescriptor::CPPTYPE_ENUM:
          value +=
              (index < 0 ? r->GetEnum(message, field) : r->GetRepeatedEnum(message, field, index))
                  ->name();
          break;
        case pb::FieldDescriptor::CPPTYPE_STRING: {
          const std::string text = index < 0 ? r->GetString(message, field)
                                             : r->GetRepeatedString(message, field, index);
          // What PATH=VALUE cannot say: the value is trimmed, and repeated values are split at
          // commas (an empty element cannot be written either). Refused, never changed.
          const bool edge_space =
              !text.empty() && (std::isspace(static_cast<unsigned char>(text.front())) != 0 ||
                                std::isspace(static_cast<unsigned char>(text.back())) != 0);
          if (edge_space || (index >= 0 && (text.empty() || text.find(',') != std::string::npos))) {
            throw std::invalid_argument(
                path + ": the string \"" + text +
                "\" cannot be written as PATH=VALUE (leading or trailing space, or a comma or "
                "an empty element in a repeated value)");
          }
          value += text;
          break;
        }
        case pb::FieldDescriptor::CPPTYPE_MESSAGE:
          break;
      }
    }
    out.push_back({path, value});
  }
}

[[noreturn]] void throw_override_error(const std::string& assignment, const std::string& path,
                                       const std::string& message) {
  throw ConfigError("--set " + assignment + ": " + (path.empty() ? "" : path + ": ") + message);
}

// The path of `PATH=VALUE` as the loader reads it (segments trimmed), "" without '='.
std::string override_path(std::string_view assignment) {
  const auto equals = assignment.find('=');
  if (equals == std::string_view::npos) return {};
  std::string path;
  for (const std::string_view segment : split(trim(assignment.substr(0, equals)), '.')) {
    if (!path.empty()) path += '.';
    path += trim(segment);
  }
  return path;
}

// "plane[2]" -> ("plane", 2); "plane" -> ("plane", -1). An index is a whole number >= 0.
std::pair<std::string, int> split_index(const std::string& quoted, const std::string& so_far,
                                        const std::string& segment) {
  const auto bracket = segment.find('[');
  if (bracket == std::string::npos) return {segment, -1};
  const std::string name(trim(std::string_view(segment).substr(0, bracket)));
  const std::string_view digits =
      trim(std::string_view(segment).substr(bracket + 1, segment.size() - bracket - 1));
  int index = -1;
  const bool closed = segment.ends_with(']') && digits.size() > 1;
  const std::string_view number = closed ? trim(digits.substr(0, digits.size() - 1)) : digits;
  const auto result = std::from_chars(number.data(), number.data() + number.size(), index);
  if (!closed || number.empty() || result.ec != std::errc{} ||
      result.ptr != number.data() + number.size() || index < 0) {
    throw_override_error(
        quoted, so_far.empty() ? name : so_far + "." + name,
        "bad index in '" + segment + "': expected " + name + "[N], N a whole number from 0");
  }
  return {name, index};
}

// The whole path of an override, resolved against the schema before anything changes. A
// repeated field takes an element index, `plane[1].offset_m` or `mass_matrix_kg[4]`; without
// one a repeated scalar is replaced whole by a list.
FieldPath resolve_override_path(const std::string& quoted, std::string_view path_text) {
  FieldPath path;
  const pb::Descriptor* type = teleop::v1::SystemConfig::descriptor();
  const std::vector<std::string_view> segments = split(path_text, '.');
  for (std::size_t i = 0; i < segments.size(); ++i) {
    const std::string so_far = dotted(path);
    const auto [segment, index] = split_index(quoted, so_far, std::string(trim(segments[i])));
    const std::string here = so_far.empty() ? segment : so_far + "." + segment;
    if (type == nullptr) {
      throw_override_error(quoted, so_far, "is a scalar, it has no field '" + segment + "'");
    }
    if (segment.empty())
      throw_override_error(quoted, std::string(path_text), "empty field name in path");
    const pb::FieldDescriptor* field = type->FindFieldByName(segment);
    if (field == nullptr) {
      throw_override_error(
          quoted, here,
          "unknown field '" + segment + "' in " + type->full_name() + suggestion(type, segment));
    }
    const bool last = i + 1 == segments.size();
    if (index >= 0 && !field->is_repeated()) {
      throw_override_error(quoted, here, "is not repeated: it takes no [index]");
    }
    if (!last && field->is_repeated() && index < 0) {
      throw_override_error(quoted, here,
                           "is a repeated section: name the element, e.g. " + here + "[0]." +
                               std::string(trim(segments[i + 1])));
    }
    path.push_back({field, index});
    type = field->message_type();
  }
  return path;
}

// Every element index of `path` names an existing element or the one after the last (which
// the override adds): checked before anything changes.
void check_indices(const LoadedConfig& config, const FieldPath& path, const std::string& quoted) {
  const pb::Message* message = &config.config;  // nullptr: inside an element still to be added
  for (std::size_t i = 0; i < path.size(); ++i) {
    const Step& step = path[i];
    const int size = message == nullptr || !step.field->is_repeated()
                         ? 0
                         : message->GetReflection()->FieldSize(*message, step.field);
    if (step.index > size) {
      const FieldPath field(path.begin(), path.begin() + static_cast<std::ptrdiff_t>(i + 1));
      const std::string name = dotted(field, false);
      throw_override_error(quoted, dotted(field),
                           "no such element: " + name + " has " + std::to_string(size) +
                               " (give [" + std::to_string(size) + "] to add one)");
    }
    if (i + 1 == path.size() || message == nullptr) continue;
    const pb::Reflection* r = message->GetReflection();
    if (step.index >= 0) {
      message =
          step.index < size ? &r->GetRepeatedMessage(*message, step.field, step.index) : nullptr;
    } else {
      message = &r->GetMessage(*message, step.field);
    }
  }
}

// The value of an override, parsed before anything changes: a section's new contents, or the
// scalars (one, or a repeated field's elements).
struct OverrideValue {
  std::vector<ScalarValue> values{};
  std::unique_ptr<pb::Message> section{};
};

std::unique_ptr<pb::Message> parse_override_section(const std::string& quoted,
                                                    const std::string& path_string,
                                                    const pb::FieldDescriptor* target,
                                                    std::string_view value_text, bool element) {
  if (target->is_repeated() && !element) {
    throw_override_error(
        quoted, path_string,
        "is a repeated section: set one element, e.g. " + path_string + "[0]={...}");
  }
  if (!value_text.starts_with('{') || !value_text.ends_with('}')) {
    throw_override_error(quoted, path_string,
                         "is a section (" + target->message_type()->full_name() +
                             "), not a scalar: set a field inside it, or give its contents "
                             "in braces, e.g. " +
                             path_string + "={}");
  }
  std::unique_ptr<pb::Message> section(
      pb::MessageFactory::generated_factory()->GetPrototype(target->message_type())->New());
  CollectingErrors errors;
  pb::TextFormat::Parser parser;
  parser.RecordErrorsTo(&errors);
  const std::string body(value_text.substr(1, value_text.size() - 2));
  if (!parser.ParseFromString(body, section.get())) {
    std::string message = "cannot parse the section";
    if (!errors.errors.empty()) {
      const ParserMessage& error = errors.errors.front();
      message +=
          " (at character " + std::to_string(error.column + 2) + " of the value): " + error.text;
    }
    throw_override_error(quoted, path_string, message);
  }
  return section;
}

OverrideValue parse_override_value(const std::string& quoted, const std::string& path_string,
                                   const Step& target_step, std::string_view value_text) {
  OverrideValue out;
  const pb::FieldDescriptor* target = target_step.field;
  const bool element = target_step.index >= 0;
  if (target->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE) {
    out.section = parse_override_section(quoted, path_string, target, value_text, element);
  } else if (target->is_repeated() && !element) {
    if (!value_text.empty()) {
      const std::vector<std::string_view> items = split(value_text, ',');
      for (std::size_t i = 0; i < items.size(); ++i) {
        std::string why;
        const auto value = parse_scalar(target, trim(items[i]), why);
        if (!value) {
          throw_override_error(quoted, path_string,
                               "cannot parse element " + std::to_string(i + 1) + " '" +
                                   std::string(trim(items[i])) + "': " + why);
        }
        out.values.push_back(*value);
      }
    }
  } else {
    std::string why;
    const auto value = parse_scalar(target, value_text, why);
    if (!value)
      throw_override_error(quoted, path_string,
                           "cannot parse '" + std::string(value_text) + "': " + why);
    out.values.push_back(*value);
  }
  return out;
}

// The forms of one quantity (issue 18): `x` (every axis), `x_per_axis` and `x_matrix`
// (mass_kg and mass_matrix_kg; coulomb_friction_N and coulomb_N_per_axis) give one value three
// ways, and a section may hold only one of them. An override replaces the value whichever form
// the file gave it in, so setting one form whole clears the others in its section.
std::string quantity_of(const std::string& field_name) {
  if (field_name == "coulomb_N_per_axis") return "coulomb_friction_N";
  std::string q = field_name;
  const std::string per_axis = "_per_axis";
  if (q.size() > per_axis.size() && q.ends_with(per_axis)) q.resize(q.size() - per_axis.size());
  const std::string matrix = "_matrix";
  if (const auto at = q.find(matrix); at != std::string::npos) q.erase(at, matrix.size());
  return q;
}

void clear_other_forms(LoadedConfig& config, pb::Message& message, const FieldPath& path,
                       const std::string& quoted) {
  const pb::FieldDescriptor* target = path.back().field;
  const std::string quantity = quantity_of(target->name());
  const pb::Descriptor* d = message.GetDescriptor();
  const pb::Reflection* r = message.GetReflection();
  for (int i = 0; i < d->field_count(); ++i) {
    const pb::FieldDescriptor* f = d->field(i);
    if (f == target || quantity_of(f->name()) != quantity) continue;
    const bool given = f->is_repeated() ? r->FieldSize(message, f) > 0 : r->HasField(message, f);
    if (!given) continue;
    r->ClearField(&message, f);
    FieldPath other = path;
    other.back() = Step{f, -1};
    config.overridden.emplace_back(dotted(other), quoted);
  }
}

// Walks down, creating sections (and so switching oneofs) as needed, and sets the value.
void write_override(LoadedConfig& config, const FieldPath& path, const OverrideValue& value,
                    const std::string& quoted) {
  pb::Message* message = &config.config;
  FieldPath walked;
  for (std::size_t i = 0; i + 1 < path.size(); ++i) {
    const pb::FieldDescriptor* field = path[i].field;
    const pb::Reflection* r = message->GetReflection();
    walked.push_back(path[i]);
    if (path[i].index >= 0) {  // an element (check_indices: existing, or the next one)
      const bool exists = path[i].index < r->FieldSize(*message, field);
      if (!exists) config.overridden.emplace_back(dotted(walked), quoted);
      message = exists ? r->MutableRepeatedMessage(message, field, path[i].index)
                       : r->AddMessage(message, field);
      continue;
    }
    if (!r->HasField(*message, field)) config.overridden.emplace_back(dotted(walked), quoted);
    message = r->MutableMessage(message, field);
  }
  const Step& target = path.back();
  if (target.index < 0) clear_other_forms(config, *message, path, quoted);
  const pb::Reflection* reflection = message->GetReflection();
  const bool append =
      target.index >= 0 && target.index == reflection->FieldSize(*message, target.field);
  if (value.section) {
    pb::Message* section =
        target.index < 0 ? reflection->MutableMessage(message, target.field)
        : append         ? reflection->AddMessage(message, target.field)
                         : reflection->MutableRepeatedMessage(message, target.field, target.index);
    section->CopyFrom(*value.section);
  } else if (target.index >= 0) {
    if (append) {
      set_scalar(*message, target.field, value.values.front());
    } else {
      set_element(*message, target.field, target.index, value.values.front());
    }
  } else {
    if (target.field->is_repeated()) reflection->ClearField(message, target.field);
    for (const ScalarValue& v : value.values) set_scalar(*message, target.field, v);
  }
  config.overridden.emplace_back(dotted(path), quoted);
}

}  // namespace

// `--set a=1 --set a=2`: which one was meant? An error naming both, never the last silently.
void check_repeated_overrides(const std::vector<std::string>& overrides) {
  std::vector<std::string> lines;
  for (std::size_t i = 0; i < overrides.size(); ++i) {
    const std::string path = override_path(overrides[i]);
    if (path.empty()) continue;
    for (std::size_t j = 0; j < i; ++j) {
      if (override_path(overrides[j]) == path) {
        lines.push_back("--set " + overrides[i] + ": " + path + ": already set by --set " +
                        overrides[j] + " (give each path once)");
        break;
      }
    }
  }
  if (lines.empty()) return;
  std::string text;
  for (const std::string& line : lines) text += (text.empty() ? "" : "\n") + line;
  throw ConfigError(text);
}

}  // namespace teleop::config::text_format

// ---------------------------------------------------------------------------------------------
// The public entry points of config_loader.hpp that are text-format tooling

namespace teleop::config {

void apply_override(LoadedConfig& config, std::string_view assignment) {
  using namespace text_format;
  const std::string quoted = std::string(assignment);
  const auto equals = assignment.find('=');
  if (equals == std::string_view::npos)
    throw_override_error(quoted, "", "expected PATH=VALUE, e.g. gains.kps=800");
  const std::string_view path_text = trim(assignment.substr(0, equals));
  const std::string_view value_text = trim(assignment.substr(equals + 1));
  if (path_text.empty())
    throw_override_error(quoted, "", "empty path; expected PATH=VALUE, e.g. gains.kps=800");
  // Resolve the whole path and parse the value before changing anything.
  const FieldPath path = resolve_override_path(quoted, path_text);
  check_indices(config, path, quoted);
  const OverrideValue value = parse_override_value(quoted, dotted(path), path.back(), value_text);
  write_override(config, path, value, quoted);
}

std::vector<FieldAssignment> set_fields(const teleop::v1::SystemConfig& config) {
  std::vector<FieldAssignment> out;
  text_format::collect_set_fields(config, "", out);
  return out;
}

}  // namespace teleop::config
