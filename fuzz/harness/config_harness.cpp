// The configuration loader (common/config): text format -> overrides -> validation -> the
// structs of the analysis, the simulator and the nodes.
//
// Input: the configuration text, optionally followed by a line "#--set" and then one `--set`
// assignment per line (at most 16). Everything documented to throw throws ConfigError; anything
// else escaping is a bug. For a configuration that loads:
// - every section converter either succeeds or throws ConfigError;
// - the analysed parameters are finite; a node's period, peer timeout and ramps are positive
//   (the loader checks their fields' signs);
// - the n-axis teleoperator's matrices are n x n and finite, its masses symmetric, its plane
//   normals unit (axes_config.hpp);
// - printed back in text format, it loads again to the same configuration;
// - set_fields() applied to an empty configuration reproduces it, or refuses a string it
//   cannot express (as documented).
#include <google/protobuf/text_format.h>
#include <google/protobuf/util/message_differencer.h>

#include <chrono>
#include <cmath>
#include <string>
#include <string_view>
#include <vector>

#include "common/config/axes_config.hpp"
#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/config/scene_loader.hpp"
#include "fuzz/harness/fuzz_check.hpp"

namespace teleop::fuzz {
namespace {

constexpr std::string_view kSetMarker = "\n#--set\n";
constexpr std::size_t kMaxOverrides = 16;

template <typename Fn>
void converts_or_refuses(Fn&& fn) {
  try {
    fn();
  } catch (const config::ConfigError&) {
    // Documented refusal.
  }
}

bool finite(std::initializer_list<double> values) {
  for (const double v : values) {
    if (!std::isfinite(v)) return false;
  }
  return true;
}

}  // namespace

int config(const std::uint8_t* data, std::size_t size) {
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  std::string_view text = input;
  std::vector<std::string> overrides;
  if (const auto marker = input.find(kSetMarker); marker != std::string_view::npos) {
    text = input.substr(0, marker);
    std::string_view rest = input.substr(marker + kSetMarker.size());
    while (!rest.empty() && overrides.size() < kMaxOverrides) {
      const auto newline = rest.find('\n');
      overrides.emplace_back(rest.substr(0, newline));
      rest = newline == std::string_view::npos ? std::string_view{} : rest.substr(newline + 1);
    }
  }

  config::LoadedConfig loaded;
  try {
    loaded = config::load_config_text(text, "fuzz.textproto", overrides);
  } catch (const config::ConfigError& e) {
    TELEOP_FUZZ_CHECK(std::string_view(e.what()).size() > 0, "an empty error message");
    return 0;
  }

  converts_or_refuses([&] {
    const TeleopParams p = config::to_teleop_params(loaded);
    TELEOP_FUZZ_CHECK(
        finite({p.sample_rate_hz, p.master_device.mass_kg, p.slave_device.mass_kg, p.gains.kpm,
                p.gains.kps, p.gains.kdm, p.gains.kds, p.gains.kvm, p.gains.kvs, p.gains.kfm,
                p.scaling.position, p.scaling.force, p.velocity_cutoff_hz}),
        "non-finite analysed parameter from a validated configuration");
    TELEOP_FUZZ_CHECK(p.sample_rate_hz > 0.0, "sample rate not positive after validation");
  });
  converts_or_refuses([&] { (void)config::to_force_loop_params(loaded); });
  converts_or_refuses([&] { (void)config::to_scene_setup(loaded); });
  // Several axes (axes_config.hpp): what validation promises of the n-axis teleoperator.
  converts_or_refuses([&] {
    const TeleopAxesParams t = config::to_axes_params(loaded);
    TELEOP_FUZZ_CHECK(t.axes >= 1 && t.axes <= kMaxAxes, "axes outside [1, 6] after validation");
    const Eigen::Index n = t.axes;
    for (const DeviceAxesParams* d : {&t.master_device, &t.slave_device}) {
      TELEOP_FUZZ_CHECK(d->mass_kg.rows() == n && d->mass_kg.cols() == n &&
                            d->mass_kg.allFinite() && d->mass_kg == d->mass_kg.transpose(),
                        "a mass matrix not n x n, finite and symmetric after validation");
      TELEOP_FUZZ_CHECK(d->damping_Ns_per_m.size() == n && d->coulomb_N.size() == n,
                        "a per-axis list of the wrong size after validation");
    }
    for (const auto* planes : {&t.master_planes, &t.slave_planes}) {
      for (const PlaneFixtureParams& p : *planes) {
        TELEOP_FUZZ_CHECK(p.normal.size() == n && std::abs(p.normal.norm() - 1.0) < 1e-12,
                          "a plane normal not a unit n-vector after validation");
      }
    }
    for (const Eigen::MatrixXd* g : {&t.gains.kpm, &t.gains.kps, &t.gains.kdm, &t.gains.kds,
                                     &t.gains.kvm, &t.gains.kvs, &t.gains.kfm}) {
      TELEOP_FUZZ_CHECK(g->rows() == n && g->cols() == n && g->allFinite(),
                        "a gain matrix not n x n and finite after validation");
    }
  });
  for (const transport::Role role : {transport::Role::kMaster, transport::Role::kSlave}) {
    converts_or_refuses([&] {
      const config::NodeSetup n = config::to_node_setup(loaded, role);
      using std::chrono::nanoseconds;
      TELEOP_FUZZ_CHECK(n.settings.period > nanoseconds{0}, "a node with a period <= 0");
      TELEOP_FUZZ_CHECK(n.sim.period == n.settings.period, "device and loop periods differ");
      TELEOP_FUZZ_CHECK(n.settings.machine.peer_timeout > nanoseconds{0},
                        "a peer timeout <= 0 (link.peer_timeout_ms is checked > 0)");
      TELEOP_FUZZ_CHECK(n.settings.machine.engage_ramp >= nanoseconds{0} &&
                            n.settings.safe_ramp >= nanoseconds{0},
                        "a negative ramp (link.*_ramp_ms are checked >= 0)");
    });
  }
  (void)config::field_origin(loaded, "gains.kps");
  (void)config::field_origin(loaded, "human.band.force_levels_N");

  // Printed and loaded again: the same configuration.
  std::string printed;
  TELEOP_FUZZ_CHECK(google::protobuf::TextFormat::PrintToString(loaded.config, &printed),
                    "a loaded configuration does not print");
  try {
    const config::LoadedConfig reloaded = config::load_config_text(printed, "printed");
    TELEOP_FUZZ_CHECK(
        google::protobuf::util::MessageDifferencer::Equals(loaded.config, reloaded.config),
        "print/load changed the configuration");
  } catch (const config::ConfigError& e) {
    fail(__FILE__, __LINE__,
         std::string("a loaded configuration, printed, is refused: ") + e.what());
  }

  // set_fields -> overrides on an empty configuration: the same configuration.
  config::LoadedConfig rebuilt;
  rebuilt.source_name = "set_fields";
  std::vector<config::FieldAssignment> fields;
  try {
    fields = config::set_fields(loaded.config);
  } catch (const std::invalid_argument&) {
    return 0;  // a string PATH=VALUE cannot express: refused, as documented
  }
  for (const config::FieldAssignment& f : fields) {
    const std::string assignment = f.path + "=" + f.value;
    try {
      config::apply_override(rebuilt, assignment);
    } catch (const config::ConfigError& e) {
      fail(__FILE__, __LINE__,
           "set_fields gave an assignment apply_override refuses: " + assignment + ": " + e.what());
    }
  }
  TELEOP_FUZZ_CHECK(
      google::protobuf::util::MessageDifferencer::Equals(loaded.config, rebuilt.config),
      "set_fields/apply_override did not reproduce the configuration");
  return 0;
}

}  // namespace teleop::fuzz
