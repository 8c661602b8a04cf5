# The fuzz harnesses as a library, shared by the libFuzzer executables (fuzz/CMakeLists.txt)
# and the regression tests (tests/unit/fuzz_regressions/), whichever is configured first.
if(NOT TARGET teleop_fuzz_harness)
  set(TELEOP_FUZZ_HARNESS_DIR ${PROJECT_SOURCE_DIR}/fuzz/harness)
  add_library(teleop_fuzz_harness STATIC
    ${TELEOP_FUZZ_HARNESS_DIR}/fuzz_check.cpp
    ${TELEOP_FUZZ_HARNESS_DIR}/node_state_harness.cpp
    ${TELEOP_FUZZ_HARNESS_DIR}/commands_harness.cpp
    ${TELEOP_FUZZ_HARNESS_DIR}/config_harness.cpp
    ${TELEOP_FUZZ_HARNESS_DIR}/mcap_harness.cpp
    ${TELEOP_FUZZ_HARNESS_DIR}/usb_harness.cpp
  )
  teleop_target_defaults(teleop_fuzz_harness)
  target_link_libraries(teleop_fuzz_harness PUBLIC teleop_transport teleop_config teleop_record
                                                   teleop_device teleop_proto)
endif()
