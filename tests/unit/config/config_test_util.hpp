// Shared helpers of the configuration tests.
#pragma once

#include <gtest/gtest.h>

#include <functional>
#include <string>

#include "common/config/config_loader.hpp"

namespace teleop::config::testing {

// The configuration of issue 2, every field given (line numbers matter to the tests: keep).
inline constexpr const char* kFullConfig =
    "sample_rate_hz: 500\n"                                                              // 1
    "master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 }\n"                        // 2
    "         fixture { stiffness_N_per_m: 0 } }\n"                                      // 3
    "slave  { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 }\n"                        // 4
    "         fixture { stiffness_N_per_m: 1500 position_m: 0.002 } }\n"                 // 5
    "gains  { kpm: 600 kps: 700 kdm: 2 kds: 3 kvm: 0.1 kvs: 0.2 kfm: 0.5 }\n"            // 6
    "scaling { position: 2 force: 0.5 }\n"                                               // 7
    "velocity_filter { cutoff_hz: 200 }\n"                                               // 8
    "round_trip_delay_samples: 3\n"                                                      // 9
    "human { band { force_levels_N: [2, 5, 8, 11, 14, 17, 20] points_per_axis: 5\n"      // 10
    "  mass_kg           { lower { intercept: 0.003 slope_per_N: 0 }\n"                  // 11
    "                      upper { intercept: 0.012 slope_per_N: 0 } }\n"                // 12
    "  damping_Ns_per_m  { lower { intercept: 0.6 slope_per_N: 0.08 }\n"                 // 13
    "                      upper { intercept: 2 slope_per_N: 0.25 } }\n"                 // 14
    "  stiffness_N_per_m { lower { intercept: 50 slope_per_N: 10 }\n"                    // 15
    "                      upper { intercept: 100 slope_per_N: 45 } } } }\n"             // 16
    "force_loop { mass_kg: 0.25 damping_Ns_per_m: 5 kp: 5 ki: 0 sample_rate_hz: 1000\n"  // 17
    "  environment_stiffness_N_per_m: 125 environment_damping_Ns_per_m: 0.1\n"           // 18
    "  sensor_average_samples: 40 }\n"                                                   // 19
    "analysis { required_damping_ratio: 0.1 stiffness_tolerance_N_per_m: 0.5 }\n";       // 20

// The smallest configuration the teleoperator analysis accepts.
inline constexpr const char* kMinimalConfig =
    "sample_rate_hz: 1000\n"
    "master { device { mass_kg: 0.04 } }\n"
    "slave { device { mass_kg: 0.036 } }\n"
    "gains { kpm: 100 kps: 100 }\n";

// The ConfigError message of `action`, or a test failure when it does not throw one.
inline std::string error_of(const std::function<void()>& action) {
  try {
    action();
  } catch (const ConfigError& error) {
    return error.what();
  }
  ADD_FAILURE() << "expected a ConfigError";
  return {};
}

// Like gmock's HasSubstr, with both strings in the failure message.
inline ::testing::AssertionResult Contains(const std::string& text, const std::string& part) {
  if (text.find(part) != std::string::npos) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "\n  text: " << text << "\n  lacks: " << part;
}

inline std::string load_error(const std::string& text) {
  return error_of([&] { (void)load_config_text(text, "TEST"); });
}

}  // namespace teleop::config::testing
