# ctest -R replay.simulate_mcap_js: `teleopctl simulate SCENE --duration 3 --out sim.mcap` (a
# 1 kHz scene), then the official TypeScript MCAP reader (tests/mcap_js/verify.mjs) reads it
# indexed and streamed, decoding every message against its schema, and checks the counts per
# topic: /config 1, /supervisor/stability 1, 3 s x 1000 Hz / 20 cycles per message on each
# node's telemetry, and 3 s x 1000 Hz on each node's /cycle channel. Then what a Foxglove user
# gets (docs/supervisor.md "Sessions", verify.mjs --session): the Header's library "teleop
# VERSION", the "teleop" and "teleop.analysis" Metadata, the scene file as the config.textproto
# Attachment byte for byte, log times that start within a minute of this test's wall clock and
# span the simulated 3 s, and /slave/cycle at 1000 messages per second of log time.
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
math(EXPR cycles "${duration} * ${rate}")
math(EXPR total "2 * ${per_side} + 2 * ${cycles} + 2")

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
string(TIMESTAMP wall_before_s "%s" UTC)
execute_process(COMMAND "${TELEOPCTL}" simulate "${SCENE}" --duration ${duration}
                        --out "${WORK_DIR}/sim.mcap"
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT (rc EQUAL 0 OR rc EQUAL 3))
  message(FATAL_ERROR "replay.simulate_mcap_js: teleopctl simulate failed (${rc}):\n${out}${err}")
endif()
file(WRITE "${WORK_DIR}/expected.json"
     "{\"messages\": ${total}, \"topics\": {\"/config\": 1, \"/master/cycle\": ${cycles}, "
     "\"/master/telemetry\": ${per_side}, \"/slave/cycle\": ${cycles}, "
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

# What a Foxglove or PlotJuggler user opens.
execute_process(COMMAND "${NODE}" "${JS_DIR}/verify.mjs" --session "${WORK_DIR}/sim.mcap"
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "replay.simulate_mcap_js: verify.mjs --session failed (${rc}):\n${err}")
endif()
function(expect what got want)
  if(NOT "${got}" STREQUAL "${want}")
    message(FATAL_ERROR "replay.simulate_mcap_js: ${what} is '${got}', expected '${want}'")
  endif()
endfunction()
string(JSON library GET "${out}" session library)
expect("the MCAP header's library" "${library}" "teleop ${VERSION}")
string(JSON version GET "${out}" session metadata teleop version)
expect("metadata teleop.version" "${version}" "${VERSION}")
string(JSON recorder GET "${out}" session metadata teleop recorder)
expect("metadata teleop.recorder" "${recorder}" "teleopctl simulate")
string(JSON verdict GET "${out}" session metadata teleop.analysis verdict)
if(NOT verdict MATCHES "^(stable|unstable|uncertain)$")
  message(FATAL_ERROR "replay.simulate_mcap_js: metadata teleop.analysis.verdict '${verdict}'")
endif()
string(JSON attachments LENGTH "${out}" session attachments)
expect("attachments" "${attachments}" "1")
string(JSON name GET "${out}" session attachments 0 name)
expect("the attachment's name" "${name}" "config.textproto")
string(JSON media GET "${out}" session attachments 0 media_type)
expect("the attachment's media type" "${media}" "text/plain")
string(JSON text GET "${out}" session attachments 0 text)
file(READ "${SCENE}" scene_bytes)
expect("the attached configuration" "${text}" "${scene_bytes}")
# Log times: ns since the epoch, from the wall clock when simulate started (within 60 s of the
# test's own reading before it), spanning the simulated duration.
string(JSON first GET "${out}" session first_log_time)
string(JSON last GET "${out}" session last_log_time)
string(LENGTH "${first}" digits)
if(digits LESS 19)
  message(FATAL_ERROR "replay.simulate_mcap_js: first log time ${first} ns is not a wall-clock "
                      "time (before 2001-09-09)")
endif()
math(EXPR first_s "${first} / 1000000000")
math(EXPR skew_s "${first_s} - ${wall_before_s}")
if(skew_s LESS -1 OR skew_s GREATER 60)
  message(FATAL_ERROR "replay.simulate_mcap_js: first log time ${first_s} s is ${skew_s} s from "
                      "the test's wall clock ${wall_before_s} s")
endif()
math(EXPR span_ms "(${last} - ${first}) / 1000000")
expect("the log-time span (ms)" "${span_ms}" "${duration}000")
# /slave/cycle: one message per cycle, 1 ms apart in log time.
string(JSON c_first GET "${out}" session topics /slave/cycle first_log_time)
string(JSON c_last GET "${out}" session topics /slave/cycle last_log_time)
string(JSON c_count GET "${out}" topics /slave/cycle)
math(EXPR c_span_us "(${c_last} - ${c_first}) / 1000")
math(EXPR per_s_milli "(${c_count} - 1) * 1000000000 / ${c_span_us}")  # messages/s x 1000
if(per_s_milli LESS 990000 OR per_s_milli GREATER 1010000)
  message(FATAL_ERROR "replay.simulate_mcap_js: /slave/cycle has ${c_count} messages over "
                      "${c_span_us} us of log time: not 1000 per second")
endif()
message(STATUS "session: ${library}, attachment ${name} (${media}), log times from ${first} ns, "
               "/slave/cycle ${c_count} messages at ${per_s_milli}/1000 per second")
