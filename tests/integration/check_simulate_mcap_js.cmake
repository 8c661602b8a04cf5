# ctest -R replay.simulate_mcap_js: `teleopctl simulate SCENE --duration 3 --out sim.mcap` (a
# 1 kHz scene), then the official TypeScript MCAP reader (tests/mcap_js/verify.mjs) reads it
# indexed and streamed, decoding every message against its schema, and checks the counts per
# topic: /config 1, /supervisor/stability 1, and 3 s x 1000 Hz / 20 cycles per message on
# each node's telemetry.
cmake_minimum_required(VERSION 3.25)
if(NOT NODE OR NOT EXISTS "${NODE}")
  message(FATAL_ERROR "replay.simulate_mcap_js: node (Node.js) not found; it is needed for the "
                      "independent MCAP reader check (tests/mcap_js)")
endif()
if(NOT EXISTS "${JS_DIR}/node_modules/@mcap/core/package.json" OR
   NOT EXISTS "${JS_DIR}/node_modules/protobufjs/package.json")
  message(FATAL_ERROR "replay.simulate_mcap_js: ${JS_DIR}/node_modules is missing: run "
                      "`npm ci --prefix tests/mcap_js` (scripts/install-deps.sh does)")
endif()
file(READ "${SCENE}" scene_text)
if(NOT scene_text MATCHES "\nsample_rate_hz: ([0-9]+)")
  message(FATAL_ERROR "replay.simulate_mcap_js: no sample_rate_hz in ${SCENE}")
endif()
set(rate ${CMAKE_MATCH_1})
set(duration 3)
math(EXPR per_side "(${duration} * ${rate} + 19) / 20")
math(EXPR total "2 * ${per_side} + 2")

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
execute_process(COMMAND "${TELEOPCTL}" simulate "${SCENE}" --duration ${duration}
                        --out "${WORK_DIR}/sim.mcap"
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT (rc EQUAL 0 OR rc EQUAL 3))
  message(FATAL_ERROR "replay.simulate_mcap_js: teleopctl simulate failed (${rc}):\n${out}${err}")
endif()
file(WRITE "${WORK_DIR}/expected.json"
     "{\"messages\": ${total}, \"topics\": {\"/config\": 1, \"/master/telemetry\": ${per_side}, "
     "\"/slave/telemetry\": ${per_side}, \"/supervisor/stability\": 1}}\n")
foreach(options "" "--stream")
  execute_process(
    COMMAND "${NODE}" "${JS_DIR}/verify.mjs" ${options} --expect "${WORK_DIR}/expected.json"
            "${WORK_DIR}/sim.mcap"
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  string(STRIP "${out}" out)
  message(STATUS "${out}")
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "replay.simulate_mcap_js: verify.mjs ${options} failed (${rc}):\n${err}")
  endif()
endforeach()
