# ctest -R record.mcap_js: writes sample session files (mcap_js_sample) and has the official
# TypeScript MCAP reader read each completely, decoding every message against its embedded
# schema (tests/mcap_js/verify.mjs), with the message counts per topic checked.
# Fails with a message saying what to install when node or node_modules is missing.
cmake_minimum_required(VERSION 3.25)
if(NOT NODE OR NOT EXISTS "${NODE}")
  message(FATAL_ERROR "record.mcap_js: node (Node.js) not found; it is needed for the "
                      "independent MCAP reader check (tests/mcap_js)")
endif()
if(NOT EXISTS "${JS_DIR}/node_modules/@mcap/core/package.json" OR
   NOT EXISTS "${JS_DIR}/node_modules/protobufjs/package.json")
  message(FATAL_ERROR "record.mcap_js: ${JS_DIR}/node_modules is missing: run "
                      "`npm ci --prefix tests/mcap_js` (scripts/install-deps.sh does)")
endif()

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
execute_process(COMMAND "${SAMPLE}" "${WORK_DIR}" RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "record.mcap_js: mcap_js_sample failed (${rc})")
endif()

# file | verify.mjs options ("-": none) | expected counts
set(cases
    "session.mcap|-|session"
    "session.mcap|--stream|session"
    "cut.mcap|--stream,--allow-truncated|cut"
    "recovered.mcap|-|recovered"
    "recovered.mcap|--stream|recovered")
foreach(c IN LISTS cases)
  string(REPLACE "|" ";" parts "${c}")
  list(GET parts 0 name)
  list(GET parts 1 options)
  list(GET parts 2 expected)
  if(options STREQUAL "-")
    set(options "")
  endif()
  string(REPLACE "," ";" options "${options}")
  execute_process(
    COMMAND "${NODE}" "${JS_DIR}/verify.mjs" ${options} --expect
            "${WORK_DIR}/${expected}.expected.json" "${WORK_DIR}/${name}"
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  string(STRIP "${out}" out)
  message(STATUS "${out}")
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "record.mcap_js: verify.mjs ${options} ${name} failed (${rc}):\n${err}")
  endif()
endforeach()
