# Post-build step of every suite: the test cases in doctest's test suite "heavy" (whole jobs and long
# numerics, see .ci/run) get the CTest label "heavy", so `ctest -LE heavy` leaves them out.
# One `--list-test-cases --test-suite=heavy` per suite (doctest_discover_tests' ADD_LABELS would
# start the suite once per test case, and its --test-case filter splits names at commas).
# Usage: cmake -DEXE=suite -DOUT=file.cmake -P heavy_labels.cmake (OUT is a TEST_INCLUDE_FILES script)
execute_process(COMMAND "${EXE}" --list-test-cases --test-suite=heavy OUTPUT_VARIABLE out RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${EXE} --list-test-cases --test-suite=heavy failed (${rc})")
endif()
string(REPLACE "\n" ";" lines "${out}")
set(script "")
foreach(line IN LISTS lines)
  if(line STREQUAL "" OR line MATCHES "^===+$" OR line MATCHES "^\\[doctest\\] ")
    continue()
  endif()
  string(APPEND script "set_tests_properties([==[${line}]==] PROPERTIES LABELS heavy)\n")
endforeach()
file(WRITE "${OUT}" "${script}")
