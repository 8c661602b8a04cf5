// The generic protobuf text-format tooling under the configuration loader (config_loader.hpp):
// parsing with field locations and readable errors (a tokeniser, the parser's context, typo
// suggestions), dotted field paths and where each value came from (a file position or a
// `--set`), `PATH=VALUE` overrides and the fields a message sets. Nothing here knows what a
// field means: the domain checks are config_loader.cpp's. Setup code only: allocates, throws.
#pragma once

#include <google/protobuf/descriptor.h>
#include <google/protobuf/io/tokenizer.h>

#include <array>
#include <charconv>
#include <string>
#include <string_view>
#include <vector>

#include "common/config/config_loader.hpp"

namespace teleop::config::text_format {

[[nodiscard]] std::string_view trim(std::string_view s);
[[nodiscard]] std::vector<std::string_view> split(std::string_view s, char separator);

// Shortest text that parses back to the same value ("0.1", "nan", "-inf", "1e+20").
template <typename Float>
[[nodiscard]] std::string format_float(Float value) {
  std::array<char, 64> buffer{};
  const auto result = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  return std::string(buffer.data(), result.ptr);
}

// " (did you mean 'kpm' or 'kps'?)": the fields of the message closest to a misspelt name (at
// most two edits, or one name a prefix of the other, ignoring case); "" when none is close.
[[nodiscard]] std::string suggestion(const google::protobuf::Descriptor* type,
                                     std::string_view name);

// ---------------------------------------------------------------------------------------------
// Field paths and where their values came from

struct Step {
  const google::protobuf::FieldDescriptor* field{};
  int index{-1};  // element of a repeated field, -1 for a singular one
};
using FieldPath = std::vector<Step>;

// "human.band.force_levels_N[2]" (with_indices) or "human.band.force_levels_N".
[[nodiscard]] std::string dotted(const FieldPath& path, bool with_indices = true);

// "human.band.force_levels_N[2]" -> steps from teleop.v1.SystemConfig. Paths are written by the
// loader, so a wrong one is a programming error (std::logic_error).
[[nodiscard]] FieldPath resolve(std::string_view text);

// "FILE:LINE:COL" of the field (or of the nearest enclosing section written in the file), or
// "--set ..." when an override set the field or created a section around it.
[[nodiscard]] std::string origin_of(const LoadedConfig& config, const FieldPath& path);

// Throws ConfigError with `lines`, one a line in their order; nothing when there are none.
void throw_if_any(const std::vector<std::string>& lines);

// Collects every problem, each "ORIGIN: PATH: message", then throws them together.
class Problems {
 public:
  explicit Problems(const LoadedConfig& config) : config_{config} {}

  void add(const FieldPath& path, const std::string& message);
  void add(std::string_view path, const std::string& message);
  // Throws ConfigError with one line per problem, in the order added; nothing when none.
  void throw_if_any() const;

 private:
  const LoadedConfig& config_;
  std::vector<std::string> lines_{};
};

// ---------------------------------------------------------------------------------------------
// Parsing and overrides

// One error of protobuf's text-format parser.
struct ParserMessage {
  int line{};    // 0-based, as protobuf reports them
  int column{};  // 0-based
  std::string text{};
};

// Keeps every error the parser reports.
class CollectingErrors final : public google::protobuf::io::ErrorCollector {
 public:
  void AddError(int line, google::protobuf::io::ColumnNumber column,
                const std::string& message) override {
    errors.push_back({line, column, message});
  }
  std::vector<ParserMessage> errors{};
};

// Parses `text` as a teleop.v1.SystemConfig, recording where each field was written; nothing
// applied or validated. Throws ConfigError with one line per parser error:
// "SOURCE:LINE:COL: PATH: message" (unknown fields with suggestions, fields set twice, oneof
// clashes, syntax errors).
[[nodiscard]] LoadedConfig parse(std::string_view text, std::string source_name);

// `--set a=1 --set a=2`: which one was meant? Throws ConfigError naming both, one line per path
// given twice (never the last silently).
void check_repeated_overrides(const std::vector<std::string>& overrides);

}  // namespace teleop::config::text_format
