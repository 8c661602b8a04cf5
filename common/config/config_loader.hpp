// Loading, overriding and validating the one SystemConfig (DESIGN §1), and turning it into the
// plain structs of common/core. Setup code only: everything here may allocate and throw.
//
// Typical use (a command-line tool):
//   auto config = teleop::config::load_config_file(path, set_assignments);  // parse, --set, check
//   const teleop::TeleopParams params = teleop::config::to_teleop_params(config);
#pragma once

#include <google/protobuf/text_format.h>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "common/core/teleop_params.hpp"
#include "teleop/v1/config.pb.h"

namespace teleop::config {

// A configuration that cannot be used. what() holds one line per problem, each naming where it
// came from and the field path, e.g.
//   examples/x.textproto:4:12: gains.kps: must be finite, got nan
//   examples/x.textproto:7:3: gains.kpx: unknown field 'kpx' in teleop.v1.Gains
//   --set master.device.mass_kg=-1: master.device.mass_kg: must be > 0, got -1
// Lines and columns are 1-based; a tab advances the column to the next multiple of 8 plus 1
// (protobuf's and the GNU convention).
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A parsed configuration together with what is needed to point at its fields in error messages.
struct LoadedConfig {
  teleop::v1::SystemConfig config{};
  // The file name as given (or the name passed to load_config_text).
  std::string source_name{};
  // Where each field was written. Immutable after parsing, so copies (e.g. one per point of a
  // parameter sweep) share it.
  std::shared_ptr<const google::protobuf::TextFormat::ParseInfoTree> locations{};
  // Dotted paths set (or message sections created) by apply_override, with the assignment that
  // did it, oldest first. Errors about values from an override name the override, not the file.
  std::vector<std::pair<std::string, std::string>> overridden{};
};

// Parses the file, applies the `path=value` overrides in order, then validates.
// Throws ConfigError on unreadable files, syntax errors, unknown fields, bad overrides and
// invalid values.
[[nodiscard]] LoadedConfig load_config_file(const std::filesystem::path& path,
                                            const std::vector<std::string>& overrides = {});

// As load_config_file, from text; source_name stands for the file in messages.
[[nodiscard]] LoadedConfig load_config_text(std::string_view text, std::string source_name,
                                            const std::vector<std::string>& overrides = {});

// Parses and applies the overrides without validating: for compile_system
// (system_compiler.hpp), which validates the result once. Throws ConfigError on unreadable
// files, syntax errors, unknown fields and bad overrides.
[[nodiscard]] LoadedConfig parse_config_file(const std::filesystem::path& path,
                                             const std::vector<std::string>& overrides = {});
[[nodiscard]] LoadedConfig parse_config_text(std::string_view text, std::string source_name,
                                             const std::vector<std::string>& overrides = {});

// Sets one field from `path=value` (the argument of `--set`), without validating the result
// (overrides may pass through invalid states; call validate() after the last one).
// - path is dotted through nested messages: `gains.kps`, `master.fixture.stiffness_N_per_m`.
//   Naming a member of a oneof selects it (`human.fixed.mass_kg=0.02` switches the human to a
//   fixed one, starting from defaults).
// - Scalars: double/float (`nan`/`inf` parse, and validate() then rejects them), integers,
//   bool (true/false/1/0), enum by value name, string.
// - A repeated scalar takes a comma list, replacing the old one: `human.band.force_levels_N=2,5,8`.
// - An element by index: `master.device.mass_matrix_kg[4]=0.3`, `slave.fixture.plane[1].offset_m=
//   0.02`, `slave.fixture.plane[0]={normal: [0, 0, 1]}`; the index one past the last adds an
//   element, a larger one is refused.
// - A message takes a text-format body in braces, replacing the old one: `human.none={}`,
//   `gains={kpm: 600 kps: 600}`.
// Throws ConfigError naming the assignment and path: no '=', unknown field, not a scalar,
// unparsable or out-of-range value.
void apply_override(LoadedConfig& config, std::string_view assignment);

// Checks every value: no NaN or infinity in any floating-point field, plus the ranges documented
// in config.proto (masses > 0, damping and stiffness >= 0, rates > 0, filter cutoff below
// Nyquist, delay in [0, 1000], band lower <= upper at every force level, ...). Sections that the
// command at hand needs are checked by to_teleop_params / to_force_loop_params.
// Throws ConfigError listing every problem.
void validate(const LoadedConfig& config);

// How many times validate() ran in this process (every caller's): the tests read it to check
// that one node start, one supervisor start or one scene validates the file once.
[[nodiscard]] std::uint64_t validation_count() noexcept;

// The teleoperator for the stability engine. Validates first, then requires sample_rate_hz,
// master.device, slave.device and gains, e.g. "FILE: missing section 'gains' (needed to analyse
// the teleoperator)". Defaults: scaling 1 and 1, no velocity filter, no delay, no fixtures,
// human = default_human_band(), required damping ratio 0, stiffness tolerance 1 N/m.
// One axis only: a file with `axes` above 1, or any n-axis field, is refused naming it
// (axes_config.hpp reads those).
[[nodiscard]] TeleopParams to_teleop_params(const LoadedConfig& config);

// The force-controlled device. Validates first, then requires the force_loop section.
[[nodiscard]] ForceLoopParams to_force_loop_params(const LoadedConfig& config);

// "FILE:LINE:COL" where the dotted field (or its nearest written section) is, or the `--set`
// that set it: for error messages of code that reads sections this file does not check.
[[nodiscard]] std::string field_origin(const LoadedConfig& config, std::string_view path);

// One scalar of a configuration, in the syntax apply_override accepts.
struct FieldAssignment {
  std::string path{};   // e.g. "gains.kps", "human.band.force_levels_N", "human.none"
  std::string value{};  // e.g. "600", "2,5,8", "{}" (a present section with nothing set in it)
};

// Every field that is set, depth-first in field-number order: scalars with a value (proto3
// plain scalars equal to 0 count as unset), repeated scalars as comma lists, and sections that
// are present but empty as "{}". Applying these to an empty configuration reproduces it; values
// round-trip exactly. A string PATH=VALUE cannot express (leading or trailing whitespace, which
// an override trims; a comma or an empty element in a repeated string, which it splits on) is
// refused with std::invalid_argument naming the field, never written changed.
[[nodiscard]] std::vector<FieldAssignment> set_fields(const teleop::v1::SystemConfig& config);

}  // namespace teleop::config
