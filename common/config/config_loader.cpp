#include "common/config/config_loader.hpp"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>
#include <google/protobuf/message.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <regex>
#include <sstream>
#include <system_error>
#include <tuple>
#include <utility>
#include <variant>

#include "common/config/parameter_space.hpp"

namespace teleop::config {
namespace {

namespace pb = google::protobuf;
using ParseInfoTree = pb::TextFormat::ParseInfoTree;

constexpr int kMaxDelaySamples = 1000;
constexpr int kMaxPointsPerAxis = 100;
constexpr int kDefaultPointsPerAxis = 4;
constexpr int kDefaultSensorAverageSamples = 50;

// ---------------------------------------------------------------------------------------------
// Small text helpers

std::string_view trim(std::string_view s) {
  const auto first = s.find_first_not_of(" \t\r\n");
  if (first == std::string_view::npos) return {};
  const auto last = s.find_last_not_of(" \t\r\n");
  return s.substr(first, last - first + 1);
}

std::vector<std::string_view> split(std::string_view s, char separator) {
  std::vector<std::string_view> parts;
  std::size_t start = 0;
  while (true) {
    const auto end = s.find(separator, start);
    if (end == std::string_view::npos) {
      parts.push_back(s.substr(start));
      return parts;
    }
    parts.push_back(s.substr(start, end - start));
    start = end + 1;
  }
}

// Shortest text that parses back to the same value ("0.1", "nan", "-inf", "1e+20").
template <typename Float>
std::string format_float(Float value) {
  std::array<char, 64> buffer{};
  const auto result = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  return std::string(buffer.data(), result.ptr);
}

std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

std::string lower_case(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

// " (did you mean 'kpm' or 'kps'?)": the fields of the message closest to a misspelt name (at
// most two edits, or one name a prefix of the other, ignoring case).
std::string suggestion(const pb::Descriptor* type, std::string_view name) {
  if (type == nullptr) return {};
  const std::string wanted = lower_case(name);
  std::vector<std::string> best;
  std::size_t best_score = 3;
  for (int i = 0; i < type->field_count(); ++i) {
    const std::string& candidate = type->field(i)->name();
    const std::string folded = lower_case(candidate);
    std::size_t score = edit_distance(wanted, folded);
    if (folded.starts_with(wanted) || wanted.starts_with(folded))
      score = std::min<std::size_t>(score, 1);
    if (score < best_score) {
      best_score = score;
      best.clear();
    }
    if (score == best_score) best.push_back(candidate);
  }
  if (best.empty()) return {};
  std::string text = " (did you mean ";
  for (std::size_t i = 0; i < best.size(); ++i) {
    if (i > 0) text += i + 1 == best.size() ? " or " : ", ";
    text += "'" + best[i] + "'";
  }
  return text + "?)";
}

// ---------------------------------------------------------------------------------------------
// Field paths and where their values came from

struct Step {
  const pb::FieldDescriptor* field{};
  int index{-1};  // element of a repeated field, -1 for a singular one
};
using FieldPath = std::vector<Step>;

std::string dotted(const FieldPath& path, bool with_indices = true) {
  std::string text;
  for (const Step& step : path) {
    if (!text.empty()) text += '.';
    text += step.field->name();
    if (with_indices && step.index >= 0) text += "[" + std::to_string(step.index) + "]";
  }
  return text;
}

// "human.band.force_levels_N[2]" -> steps. Paths here are written by this file, so a wrong one is
// a programming error.
FieldPath resolve(std::string_view text) {
  FieldPath path;
  const pb::Descriptor* type = teleop::v1::SystemConfig::descriptor();
  for (std::string_view segment : split(text, '.')) {
    int index = -1;
    if (const auto bracket = segment.find('['); bracket != std::string_view::npos) {
      const std::string_view digits = segment.substr(bracket + 1, segment.size() - bracket - 2);
      std::from_chars(digits.data(), digits.data() + digits.size(), index);
      segment = segment.substr(0, bracket);
    }
    const pb::FieldDescriptor* field =
        type == nullptr ? nullptr : type->FindFieldByName(std::string(segment));
    if (field == nullptr)
      throw std::logic_error("config_loader: bad field path " + std::string(text));
    path.push_back({field, index});
    type = field->message_type();
  }
  return path;
}

// Number of elements of the repeated field at the end of `path` in the configuration.
int element_count(const LoadedConfig& config, const FieldPath& path) {
  const pb::Message* message = &config.config;
  for (std::size_t i = 0; i + 1 < path.size(); ++i) {
    const pb::Reflection* r = message->GetReflection();
    message = path[i].field->is_repeated()
                  ? &r->GetRepeatedMessage(*message, path[i].field, path[i].index)
                  : &r->GetMessage(*message, path[i].field);
  }
  return message->GetReflection()->FieldSize(*message, path.back().field);
}

int recorded_count(const ParseInfoTree& tree, const pb::FieldDescriptor* field) {
  int count = 0;
  while (tree.GetLocation(field, count).line >= 0) ++count;
  return count;
}

// Where the field of `path` was written in the file, if it was.
std::optional<pb::TextFormat::ParseLocation> location_of(const LoadedConfig& config,
                                                         const FieldPath& path) {
  if (config.locations == nullptr || path.empty()) return std::nullopt;
  const ParseInfoTree* tree = config.locations.get();
  for (std::size_t i = 0; i + 1 < path.size(); ++i) {
    tree = tree->GetTreeForNested(path[i].field, path[i].field->is_repeated() ? path[i].index : -1);
    if (tree == nullptr) return std::nullopt;
  }
  const Step& last = path.back();
  int index = -1;
  if (last.field->is_repeated()) {
    // The parser records one location per `name: value` or `name: [list]`, not per element: use
    // the element's own only when every element was written separately, else the field's first.
    index = 0;
    if (last.index > 0 && recorded_count(*tree, last.field) == element_count(config, path)) {
      index = last.index;
    }
  }
  const pb::TextFormat::ParseLocation location = tree->GetLocation(last.field, index);
  if (location.line < 0) return std::nullopt;
  return location;
}

std::string describe_location(const LoadedConfig& config,
                              const pb::TextFormat::ParseLocation& location) {
  return config.source_name + ":" + std::to_string(location.line + 1) + ":" +
         std::to_string(location.column + 1);
}

// "FILE:LINE:COL" of the field (or of the nearest enclosing section written in the file), or
// "--set ..." when an override set the field or created a section around it.
std::string origin_of(const LoadedConfig& config, const FieldPath& path) {
  const std::string plain = dotted(path, false);
  for (auto it = config.overridden.rbegin(); it != config.overridden.rend(); ++it) {
    const std::string& set_path = it->first;
    if (plain == set_path || (plain.size() > set_path.size() && plain.starts_with(set_path) &&
                              plain[set_path.size()] == '.')) {
      return "--set " + it->second;
    }
  }
  for (std::size_t length = path.size(); length > 0; --length) {
    const FieldPath prefix(path.begin(), path.begin() + static_cast<std::ptrdiff_t>(length));
    if (const auto location = location_of(config, prefix)) {
      return describe_location(config, *location);
    }
  }
  return config.source_name;
}

// Collects every problem, then throws them together.
class Problems {
 public:
  explicit Problems(const LoadedConfig& config) : config_{config} {}

  void add(const FieldPath& path, const std::string& message) {
    lines_.push_back(origin_of(config_, path) + ": " + dotted(path) + ": " + message);
  }
  void add(std::string_view path, const std::string& message) { add(resolve(path), message); }

  void throw_if_any() const {
    if (lines_.empty()) return;
    std::string text;
    for (const std::string& line : lines_) {
      if (!text.empty()) text += '\n';
      text += line;
    }
    throw ConfigError(text);
  }

 private:
  const LoadedConfig& config_;
  std::vector<std::string> lines_{};
};

// ---------------------------------------------------------------------------------------------
// Parsing

struct ParserMessage {
  int line{};    // 0-based, as protobuf reports them
  int column{};  // 0-based
  std::string text{};
};

class CollectingErrors final : public pb::io::ErrorCollector {
 public:
  void AddError(int line, pb::io::ColumnNumber column, const std::string& message) override {
    errors.push_back({line, column, message});
  }
  std::vector<ParserMessage> errors{};
};

class IgnoringErrors final : public pb::io::ErrorCollector {
 public:
  void AddError(int, pb::io::ColumnNumber, const std::string&) override {}
};

struct Token {
  pb::io::Tokenizer::TokenType type{};
  std::string text{};
  int line{};
  int column{};
};

bool before(const Token& token, int line, int column) {
  return token.line < line || (token.line == line && token.column < column);
}

// The tokens of a text-format document, tokenized as the text-format parser does.
std::vector<Token> tokenize(std::string_view text) {
  pb::io::ArrayInputStream input(text.data(), static_cast<int>(text.size()));
  IgnoringErrors ignore;
  pb::io::Tokenizer tokenizer(&input, &ignore);
  tokenizer.set_comment_style(pb::io::Tokenizer::SH_COMMENT_STYLE);
  tokenizer.set_allow_f_after_float(true);
  tokenizer.set_require_space_after_number(false);
  tokenizer.set_allow_multiline_strings(true);
  std::vector<Token> tokens;
  while (tokenizer.Next()) {
    const auto& current = tokenizer.current();
    tokens.push_back({current.type, current.text, current.line, current.column});
  }
  return tokens;
}

bool is_symbol(const Token& token, std::string_view symbol) {
  return token.type == pb::io::Tokenizer::TYPE_SYMBOL && token.text == symbol;
}

// What the parser was inside of when it stopped: the enclosing sections, and the field whose
// value it was reading (if the error is in a value).
struct ParseContext {
  std::vector<std::string> sections{};
  std::string field{};
};

ParseContext context_at(const std::vector<Token>& tokens, int line, int column) {
  ParseContext context;
  std::string last_name;  // last field name at the current depth
  bool in_list = false;
  std::size_t end = 0;
  while (end < tokens.size() && before(tokens[end], line, column)) ++end;
  for (std::size_t i = 0; i < end; ++i) {
    const Token& token = tokens[i];
    const bool followed_by_value =
        i + 1 < tokens.size() && (is_symbol(tokens[i + 1], ":") || is_symbol(tokens[i + 1], "{") ||
                                  is_symbol(tokens[i + 1], "<"));
    if (token.type == pb::io::Tokenizer::TYPE_IDENTIFIER && followed_by_value && !in_list) {
      last_name = token.text;
    } else if (is_symbol(token, "{") || is_symbol(token, "<")) {
      context.sections.push_back(last_name);
      last_name.clear();
      in_list = false;
    } else if (is_symbol(token, "}") || is_symbol(token, ">")) {
      if (!context.sections.empty()) {
        last_name = context.sections.back();
        context.sections.pop_back();
      }
    } else if (is_symbol(token, "[")) {
      in_list = true;
    } else if (is_symbol(token, "]")) {
      in_list = false;
    }
  }
  // The error is in a value when it follows `name:` (or `name: -`) or lies inside `name: [...]`.
  const auto previous = [&](std::size_t back) -> const Token* {
    return end >= back ? &tokens[end - back] : nullptr;
  };
  const Token* one = previous(1);
  const Token* two = previous(2);
  if (in_list || (one != nullptr && is_symbol(*one, ":")) ||
      (one != nullptr && two != nullptr && is_symbol(*one, "-") && is_symbol(*two, ":"))) {
    context.field = last_name;
  }
  return context;
}

// The last occurrence of identifier `name` before the position (the parser reports some errors
// at the token after the field name; point at the name itself).
std::pair<int, int> name_position(const std::vector<Token>& tokens, const std::string& name,
                                  int line, int column) {
  std::pair<int, int> position{line, column};
  for (const Token& token : tokens) {
    if (!before(token, line, column)) break;
    if (token.type == pb::io::Tokenizer::TYPE_IDENTIFIER && token.text == name) {
      position = {token.line, token.column};
    }
  }
  return position;
}

std::string join_path(const std::vector<std::string>& sections, const std::string& field) {
  std::string path;
  for (const std::string& section : sections) {
    if (!path.empty()) path += '.';
    path += section;
  }
  if (!field.empty()) {
    if (!path.empty()) path += '.';
    path += field;
  }
  return path;
}

// One parser error as "FILE:LINE:COL: PATH: message".
std::string describe_parse_error(std::string_view source_name, const std::vector<Token>& tokens,
                                 const ParserMessage& error) {
  static const std::regex unknown_field{
      R"re(Message type "([^"]+)" has no field named "([^"]+)"\.)re"};
  static const std::regex repeated_field{
      R"re(Non-repeated field "([^"]+)" is specified multiple times\.)re"};
  static const std::regex oneof_clash{
      R"re(Field "([^"]+)" is specified along with field "([^"]+)", another member of oneof "([^"]+)"\.)re"};

  const ParseContext context = context_at(tokens, error.line, error.column);
  int line = error.line;
  int column = error.column;
  std::string path;
  std::string message;
  std::smatch match;
  if (std::regex_search(error.text, match, unknown_field)) {
    const std::string type = match[1];
    const std::string name = match[2];
    std::tie(line, column) = name_position(tokens, name, error.line, error.column);
    path = join_path(context.sections, name);
    message = "unknown field '" + name + "' in " + type +
              suggestion(pb::DescriptorPool::generated_pool()->FindMessageTypeByName(type), name);
  } else if (std::regex_search(error.text, match, repeated_field)) {
    const std::string name = match[1];
    std::tie(line, column) = name_position(tokens, name, error.line, error.column);
    path = join_path(context.sections, name);
    message = "set more than once";
  } else if (std::regex_search(error.text, match, oneof_clash)) {
    const std::string name = match[1];
    std::tie(line, column) = name_position(tokens, name, error.line, error.column);
    path = join_path(context.sections, name);
    message = "'" + std::string(match[2]) + "' is already set; give only one of the members of '" +
              std::string(match[3]) + "'";
  } else {
    path = join_path(context.sections, context.field);
    message = error.text;
    if (message.ends_with("got: ")) message += "end of input";
  }
  std::string text = std::string(source_name) + ":" + std::to_string(line + 1) + ":" +
                     std::to_string(column + 1) + ": ";
  if (!path.empty()) text += path + ": ";
  return text + message;
}

// ---------------------------------------------------------------------------------------------
// Overrides

using ScalarValue = std::variant<double, float, std::int32_t, std::int64_t, std::uint32_t,
                                 std::uint64_t, bool, const pb::EnumValueDescriptor*, std::string>;

// from_chars rejects the leading '+' that people (and strtod) accept.
std::string_view without_plus(std::string_view text) {
  return text.size() > 1 && text.front() == '+' && text[1] != '-' ? text.substr(1) : text;
}

template <typename Integer>
std::optional<Integer> parse_integer(std::string_view text, std::string& why) {
  text = without_plus(text);
  Integer value{};
  const auto result = std::from_chars(text.data(), text.data() + text.size(), value);
  if (result.ec == std::errc::result_out_of_range) {
    why = "out of range";
    return std::nullopt;
  }
  if (result.ec != std::errc{} || result.ptr != text.data() + text.size()) {
    why = "not an integer";
    return std::nullopt;
  }
  return value;
}

std::optional<double> parse_double(std::string_view text, std::string& why) {
  text = without_plus(text);
  double value{};
  const auto result = std::from_chars(text.data(), text.data() + text.size(), value);
  if (result.ec == std::errc::result_out_of_range) {
    why = "out of range";
    return std::nullopt;
  }
  if (result.ec != std::errc{} || result.ptr != text.data() + text.size()) {
    why = "not a number";
    return std::nullopt;
  }
  return value;
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

// ---------------------------------------------------------------------------------------------
// Validation

// Every numeric value anywhere in the configuration, by the one parameter space
// (parameter_space.hpp): finite, and the sign and range config.proto documents for the field.
void check_fields(const pb::Message& message, Problems& problems) {
  for (const FieldProblem& p : teleop::config::check_fields(message)) {
    problems.add(p.path, p.message);
  }
}

// Endpoints: each well formed (tcp ports 1-65535), and every bound one distinct from the others.
void check_endpoints(const teleop::v1::SystemConfig& c, Problems& problems) {
  const std::vector<BoundEndpoint> bound = bound_endpoints(c);
  for (const BoundEndpoint& e : bound) {
    if (e.defaulted) continue;
    if (const std::string why = check_endpoint(e.endpoint); !why.empty()) {
      problems.add(e.path, why);
    }
  }
  for (const char* side : {"master", "slave"}) {
    const teleop::v1::Node& node =
        std::string_view(side) == "master" ? c.master().node() : c.slave().node();
    if (node.peer_state_endpoint().empty()) continue;
    if (const std::string why = check_endpoint(node.peer_state_endpoint()); !why.empty()) {
      problems.add(std::string(side) + ".node.peer_state_endpoint", why);
    }
  }
  for (std::size_t i = 0; i < bound.size(); ++i) {
    for (std::size_t j = 0; j < i; ++j) {
      if (!endpoints_clash(bound[i].endpoint, bound[j].endpoint)) continue;
      // Name the one written by the user (a default clashing with a written one).
      const BoundEndpoint& named = bound[i].defaulted && !bound[j].defaulted ? bound[j] : bound[i];
      const BoundEndpoint& other = &named == &bound[i] ? bound[j] : bound[i];
      problems.add(named.path, "\"" + named.endpoint + "\" is also " + other.path +
                                   (other.defaulted ? " (its default)" : "") +
                                   ": every bound endpoint must be distinct");
    }
  }
}

// Signs and ranges of single fields are check_fields' (the parameter space); what follows are
// the rules that involve presence or more than one field.
void require_present(Problems& problems, std::string_view path, bool present,
                     std::string_view why) {
  if (!present) problems.add(path, "missing (" + std::string(why) + ")");
}

void check_device(Problems& problems, const std::string& side, const teleop::v1::Side& config) {
  if (config.has_device()) {
    const std::string prefix = side + ".device.";
    require_present(problems, prefix + "mass_kg", config.device().has_mass_kg(),
                    "a device needs its mass");
  }
}

void check_band(Problems& problems, const teleop::v1::HumanBand& band) {
  const std::string prefix = "human.band.";
  if (band.force_levels_n_size() == 0) {
    problems.add(prefix + "force_levels_N", "missing (a band needs at least one force level)");
  }
  if (band.has_points_per_axis() &&
      (band.points_per_axis() < 2 || band.points_per_axis() > kMaxPointsPerAxis)) {
    problems.add(prefix + "points_per_axis", "must be in [2, " + std::to_string(kMaxPointsPerAxis) +
                                                 "], got " +
                                                 std::to_string(band.points_per_axis()));
  }

  struct Axis {
    const char* name;
    bool present;
    const teleop::v1::ParameterBand& bounds;
    bool lower_must_be_positive;
  };
  const std::array<Axis, 3> axes{{
      {"mass_kg", band.has_mass_kg(), band.mass_kg(), true},
      {"damping_Ns_per_m", band.has_damping_ns_per_m(), band.damping_ns_per_m(), false},
      {"stiffness_N_per_m", band.has_stiffness_n_per_m(), band.stiffness_n_per_m(), false},
  }};
  for (const Axis& axis : axes) {
    const std::string path = prefix + axis.name;
    if (!axis.present) {
      problems.add(path, "missing (a band needs lower and upper lines of every parameter)");
      continue;
    }
    require_present(problems, path + ".lower", axis.bounds.has_lower(), "the lower bounding line");
    require_present(problems, path + ".upper", axis.bounds.has_upper(), "the upper bounding line");
    if (!axis.bounds.has_lower() || !axis.bounds.has_upper()) continue;
    const LinearBound lower{axis.bounds.lower().intercept(), axis.bounds.lower().slope_per_n()};
    const LinearBound upper{axis.bounds.upper().intercept(), axis.bounds.upper().slope_per_n()};
    // The values the lines give obey the fixed human's rule of the same axis (one parameter
    // space): its ceiling.
    const FieldRule* rule =
        rule_for(teleop::v1::HumanImpedance::descriptor()->FindFieldByName(axis.name));
    const double ceiling = rule != nullptr ? rule->max : std::numeric_limits<double>::max();
    // One report per axis: the first force level where each rule fails.
    bool lower_reported = false;
    bool order_reported = false;
    bool ceiling_reported = false;
    for (const double force_N : band.force_levels_n()) {
      const double low = lower.at(force_N);
      const double high = upper.at(force_N);
      if (!std::isfinite(force_N) || !std::isfinite(low) || !std::isfinite(high)) continue;
      const std::string at = " at force level " + format_float(force_N) + " N";
      const bool lower_bad = axis.lower_must_be_positive ? !(low > 0.0) : low < 0.0;
      if (lower_bad && !lower_reported) {
        problems.add(path + ".lower", std::string("must be ") +
                                          (axis.lower_must_be_positive ? "> 0" : ">= 0") + at +
                                          ", got " + format_float(low));
        lower_reported = true;
      }
      if (!(high <= ceiling) && !ceiling_reported) {
        problems.add(path + ".upper",
                     "must be <= " + format_float(ceiling) + at + ", got " + format_float(high));
        ceiling_reported = true;
      }
      if (low > high && !order_reported) {
        problems.add(path, "lower bound " + format_float(low) + " exceeds upper bound " +
                               format_float(high) + at);
        order_reported = true;
      }
    }
  }
}

void check_ranges(const teleop::v1::SystemConfig& c, Problems& problems) {
  if (c.has_master()) check_device(problems, "master", c.master());
  if (c.has_slave()) check_device(problems, "slave", c.slave());
  if (c.has_scaling() && c.scaling().has_position() && c.scaling().position() == 0.0) {
    problems.add("scaling.position", "must not be 0 (the slave would not follow the master)");
  }
  if (c.has_round_trip_delay_samples() &&
      (c.round_trip_delay_samples() < 0 || c.round_trip_delay_samples() > kMaxDelaySamples)) {
    problems.add("round_trip_delay_samples", "must be in [0, " + std::to_string(kMaxDelaySamples) +
                                                 "], got " +
                                                 std::to_string(c.round_trip_delay_samples()));
  }
  if (c.has_human()) {
    const teleop::v1::Human& human = c.human();
    switch (human.kind_case()) {
      case teleop::v1::Human::kFixed:
        break;
      case teleop::v1::Human::kBand:
        check_band(problems, human.band());
        break;
      case teleop::v1::Human::kNone:
        break;
      case teleop::v1::Human::KIND_NOT_SET:
        problems.add("human",
                     "give one of fixed, band or none (or leave out the section for the "
                     "default band)");
        break;
    }
  }
  if (c.has_force_loop()) {
    const teleop::v1::ForceLoop& loop = c.force_loop();
    require_present(problems, "force_loop.mass_kg", loop.has_mass_kg(), "the device's mass");
    require_present(problems, "force_loop.sample_rate_hz", loop.has_sample_rate_hz(),
                    "the loop's rate");
    if (loop.has_sensor_average_samples() && loop.sensor_average_samples() < 1) {
      problems.add("force_loop.sensor_average_samples",
                   "must be >= 1, got " + std::to_string(loop.sensor_average_samples()));
    }
  }
  if (c.has_analysis()) {
    const double ratio = c.analysis().required_damping_ratio();
    if (std::isfinite(ratio) && (ratio < 0.0 || ratio >= 1.0)) {
      problems.add("analysis.required_damping_ratio",
                   "must be in [0, 1), got " + format_float(ratio));
    }
  }
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

LinearBound to_bound(const teleop::v1::LinearBound& bound) {
  return {bound.intercept(), bound.slope_per_n()};
}

ParameterBand to_band(const teleop::v1::ParameterBand& band) {
  return {to_bound(band.lower()), to_bound(band.upper())};
}

DeviceParams to_device(const teleop::v1::Device& device) {
  return {device.mass_kg(), device.damping_ns_per_m()};
}

FixtureParams to_fixture(const teleop::v1::Side& side) {
  if (!side.has_fixture()) return {};
  return {side.fixture().stiffness_n_per_m(), side.fixture().position_m()};
}

void require_section(const LoadedConfig& config, std::vector<std::string>& missing, bool present,
                     std::string_view name, std::string_view purpose) {
  if (!present) {
    missing.push_back(config.source_name + ": missing section '" + std::string(name) +
                      "' (needed to " + std::string(purpose) + ")");
  }
}

void throw_missing(const std::vector<std::string>& missing) {
  if (missing.empty()) return;
  std::string text;
  for (const std::string& line : missing) {
    if (!text.empty()) text += '\n';
    text += line;
  }
  throw ConfigError(text);
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

}  // namespace

// ---------------------------------------------------------------------------------------------

LoadedConfig load_config_text(std::string_view text, std::string source_name,
                              const std::vector<std::string>& overrides) {
  LoadedConfig loaded;
  loaded.source_name = std::move(source_name);
  if (text.size() > static_cast<std::size_t>(std::numeric_limits<int>::max())) {
    throw ConfigError(loaded.source_name + ": too large to be a configuration");
  }
  auto locations = std::make_shared<ParseInfoTree>();
  CollectingErrors errors;
  pb::TextFormat::Parser parser;
  parser.RecordErrorsTo(&errors);
  parser.WriteLocationsTo(locations.get());
  const bool parsed = parser.ParseFromString(std::string(text), &loaded.config);
  if (!parsed || !errors.errors.empty()) {
    const std::vector<Token> tokens = tokenize(text);
    std::string message;
    for (const ParserMessage& error : errors.errors) {
      if (!message.empty()) message += '\n';
      message += describe_parse_error(loaded.source_name, tokens, error);
    }
    if (message.empty()) message = loaded.source_name + ": cannot parse";
    throw ConfigError(message);
  }
  loaded.locations = std::move(locations);
  check_repeated_overrides(overrides);
  for (const std::string& assignment : overrides) apply_override(loaded, assignment);
  validate(loaded);
  return loaded;
}

LoadedConfig load_config_file(const std::filesystem::path& path,
                              const std::vector<std::string>& overrides) {
  const std::string name = path.string();
  std::error_code status_error;
  if (std::filesystem::is_directory(path, status_error)) {
    throw ConfigError(name + ": is a directory, not a configuration file");
  }
  std::ifstream file(path, std::ios::binary);
  if (!file) {
    throw ConfigError(name + ": cannot open: " + std::strerror(errno));
  }
  std::ostringstream contents;
  contents << file.rdbuf();
  if (file.bad()) throw ConfigError(name + ": cannot read: " + std::strerror(errno));
  return load_config_text(contents.str(), name, overrides);
}

void apply_override(LoadedConfig& config, std::string_view assignment) {
  const std::string quoted = std::string(assignment);
  const auto equals = assignment.find('=');
  if (equals == std::string_view::npos)
    throw_override_error(quoted, "", "expected PATH=VALUE, e.g. gains.kps=800");
  const std::string_view path_text = trim(assignment.substr(0, equals));
  const std::string_view value_text = trim(assignment.substr(equals + 1));
  if (path_text.empty())
    throw_override_error(quoted, "", "empty path; expected PATH=VALUE, e.g. gains.kps=800");

  // Resolve the whole path against the schema before changing anything.
  FieldPath path;
  const pb::Descriptor* type = teleop::v1::SystemConfig::descriptor();
  const std::vector<std::string_view> segments = split(path_text, '.');
  for (std::size_t i = 0; i < segments.size(); ++i) {
    const std::string segment(trim(segments[i]));
    const std::string so_far = dotted(path);
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
    if (!last && field->is_repeated()) {
      throw_override_error(quoted, here,
                           "is a repeated section; overriding inside it is not supported");
    }
    path.push_back({field, -1});
    type = field->message_type();
  }
  const std::string path_string = dotted(path);
  const pb::FieldDescriptor* target = path.back().field;
  const bool is_message = target->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE;

  // Parse the value before changing anything.
  std::vector<ScalarValue> values;
  std::unique_ptr<pb::Message> section;
  if (is_message) {
    if (target->is_repeated())
      throw_override_error(quoted, path_string, "is a repeated section; not supported by --set");
    if (!value_text.starts_with('{') || !value_text.ends_with('}')) {
      throw_override_error(quoted, path_string,
                           "is a section (" + target->message_type()->full_name() +
                               "), not a scalar: set a field inside it, or give its contents "
                               "in braces, e.g. " +
                               path_string + "={}");
    }
    section.reset(
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
  } else if (target->is_repeated()) {
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
        values.push_back(*value);
      }
    }
  } else {
    std::string why;
    const auto value = parse_scalar(target, value_text, why);
    if (!value)
      throw_override_error(quoted, path_string,
                           "cannot parse '" + std::string(value_text) + "': " + why);
    values.push_back(*value);
  }

  // Walk down, creating sections (and so switching oneofs) as needed.
  pb::Message* message = &config.config;
  FieldPath walked;
  for (std::size_t i = 0; i + 1 < path.size(); ++i) {
    const pb::FieldDescriptor* field = path[i].field;
    walked.push_back(path[i]);
    if (!message->GetReflection()->HasField(*message, field)) {
      config.overridden.emplace_back(dotted(walked), quoted);
    }
    message = message->GetReflection()->MutableMessage(message, field);
  }
  const pb::Reflection* reflection = message->GetReflection();
  if (is_message) {
    reflection->MutableMessage(message, target)->CopyFrom(*section);
  } else {
    if (target->is_repeated()) reflection->ClearField(message, target);
    for (const ScalarValue& value : values) set_scalar(*message, target, value);
  }
  config.overridden.emplace_back(path_string, quoted);
}

void validate(const LoadedConfig& config) {
  Problems problems(config);
  check_fields(config.config, problems);
  check_ranges(config.config, problems);
  check_endpoints(config.config, problems);
  problems.throw_if_any();
}

TeleopParams to_teleop_params(const LoadedConfig& config) {
  validate(config);
  const teleop::v1::SystemConfig& c = config.config;
  constexpr std::string_view kPurpose = "analyse the teleoperator";
  std::vector<std::string> missing;
  require_section(config, missing, c.has_sample_rate_hz(), "sample_rate_hz", kPurpose);
  require_section(config, missing, c.has_master() && c.master().has_device(), "master.device",
                  kPurpose);
  require_section(config, missing, c.has_slave() && c.slave().has_device(), "slave.device",
                  kPurpose);
  require_section(config, missing, c.has_gains(), "gains", kPurpose);
  throw_missing(missing);

  TeleopParams params;
  params.sample_rate_hz = c.sample_rate_hz();
  params.master_device = to_device(c.master().device());
  params.slave_device = to_device(c.slave().device());
  params.master_fixture = to_fixture(c.master());
  params.slave_fixture = to_fixture(c.slave());
  const teleop::v1::Gains& gains = c.gains();
  params.gains = {gains.kpm(), gains.kps(), gains.kdm(), gains.kds(),
                  gains.kvm(), gains.kvs(), gains.kfm()};
  if (c.has_scaling()) {
    if (c.scaling().has_position()) params.scaling.position = c.scaling().position();
    if (c.scaling().has_force()) params.scaling.force = c.scaling().force();
  }
  params.velocity_cutoff_hz = c.velocity_filter().cutoff_hz();
  params.round_trip_delay_samples = c.round_trip_delay_samples();

  if (!c.has_human()) {
    params.human.kind = HumanKind::kBand;
    params.human.band = default_human_band();
  } else if (c.human().has_fixed()) {
    const teleop::v1::HumanImpedance& fixed = c.human().fixed();
    params.human.kind = HumanKind::kFixed;
    params.human.fixed = {fixed.mass_kg(), fixed.damping_ns_per_m(), fixed.stiffness_n_per_m()};
  } else if (c.human().has_band()) {
    const teleop::v1::HumanBand& band = c.human().band();
    params.human.kind = HumanKind::kBand;
    params.human.band.force_levels_N.assign(band.force_levels_n().begin(),
                                            band.force_levels_n().end());
    params.human.band.points_per_axis =
        band.has_points_per_axis() ? band.points_per_axis() : kDefaultPointsPerAxis;
    params.human.band.mass_kg = to_band(band.mass_kg());
    params.human.band.damping_Ns_per_m = to_band(band.damping_ns_per_m());
    params.human.band.stiffness_N_per_m = to_band(band.stiffness_n_per_m());
  } else {
    params.human.kind = HumanKind::kNone;
  }

  params.analysis.required_damping_ratio = c.analysis().required_damping_ratio();
  if (c.analysis().has_stiffness_tolerance_n_per_m()) {
    params.analysis.stiffness_tolerance_N_per_m = c.analysis().stiffness_tolerance_n_per_m();
  }
  return params;
}

ForceLoopParams to_force_loop_params(const LoadedConfig& config) {
  validate(config);
  std::vector<std::string> missing;
  require_section(config, missing, config.config.has_force_loop(), "force_loop",
                  "analyse the force loop");
  throw_missing(missing);
  const teleop::v1::ForceLoop& loop = config.config.force_loop();
  ForceLoopParams params;
  params.mass_kg = loop.mass_kg();
  params.damping_Ns_per_m = loop.damping_ns_per_m();
  params.kp = loop.kp();
  params.ki = loop.ki();
  params.sample_rate_hz = loop.sample_rate_hz();
  params.environment_stiffness_N_per_m = loop.environment_stiffness_n_per_m();
  params.environment_damping_Ns_per_m = loop.environment_damping_ns_per_m();
  params.sensor_average_samples = loop.has_sensor_average_samples() ? loop.sensor_average_samples()
                                                                    : kDefaultSensorAverageSamples;
  return params;
}

std::string field_origin(const LoadedConfig& config, std::string_view path) {
  return origin_of(config, resolve(path));
}

std::vector<FieldAssignment> set_fields(const teleop::v1::SystemConfig& config) {
  std::vector<FieldAssignment> out;
  collect_set_fields(config, "", out);
  return out;
}

}  // namespace teleop::config
