#include "common/config/text_format.hpp"

#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>
#include <google/protobuf/message.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <regex>
#include <stdexcept>
#include <tuple>
#include <utility>
#include <variant>

namespace teleop::config::text_format {
namespace {

namespace pb = google::protobuf;
using ParseInfoTree = pb::TextFormat::ParseInfoTree;

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

}  // namespace

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

std::string dotted(const FieldPath& path, bool with_indices) {
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

namespace {

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

}  // namespace

// "FILE:LINE:COL" of the field (or of the nearest enclosing section written in the file), or
// "--set ..." when an override set the field or created a section around it.
namespace {

// Whether an override of `set_path` changed the value at `path`: the same field, one inside
// it (".x", or an element "[i]"), or an element of it (the override set `path[i]`, so the
// whole of `path`, e.g. a matrix that is no longer symmetric, is the override's doing).
bool overrides(const std::string& set_path, const std::string& path) {
  const auto below = [](const std::string& longer, const std::string& prefix,
                        std::string_view separators) {
    return longer.size() > prefix.size() && longer.starts_with(prefix) &&
           separators.find(longer[prefix.size()]) != std::string_view::npos;
  };
  return path == set_path || below(path, set_path, ".[") || below(set_path, path, "[");
}

}  // namespace

std::string origin_of(const LoadedConfig& config, const FieldPath& path) {
  const std::string plain = dotted(path, false);
  const std::string indexed = dotted(path, true);
  for (auto it = config.overridden.rbegin(); it != config.overridden.rend(); ++it) {
    if (overrides(it->first, plain) || overrides(it->first, indexed)) {
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

void Problems::add(const FieldPath& path, const std::string& message) {
  lines_.push_back(origin_of(config_, path) + ": " + dotted(path) + ": " + message);
}

void Problems::add(std::string_view path, const std::string& message) {
  add(resolve(path), message);
}

void throw_if_any(const std::vector<std::string>& lines) {
  if (lines.empty()) return;
  std::string text;
  for (const std::string& line : lines) {
    if (!text.empty()) text += '\n';
    text += line;
  }
  throw ConfigError(text);
}

void Problems::throw_if_any() const { text_format::throw_if_any(lines_); }

namespace {

// ---------------------------------------------------------------------------------------------
// Parsing

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

}  // namespace

LoadedConfig parse(std::string_view text, std::string source_name) {
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
  return loaded;
}

}  // namespace teleop::config::text_format

namespace teleop::config {

std::string field_origin(const LoadedConfig& config, std::string_view path) {
  return text_format::origin_of(config, text_format::resolve(path));
}

}  // namespace teleop::config
