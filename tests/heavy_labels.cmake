# Post-build step of every suite: labels its CTest tests.
#   - every test case gets the suite's name as a label (e.g. "cad_tests"): `ctest -L '^cad_tests$'`
#     runs one suite (.ci/sanitize runs the suites that load Open CASCADE's translators apart, with
#     LeakSanitizer's slow unwinder, see .ci/lsan.supp);
#   - the test cases in doctest's test suite "heavy" (whole jobs and long numerics, see .ci/run) also
#     get the label "heavy", so `ctest -LE heavy` leaves them out, and a COST of 10 (the others 1):
#     `ctest -j N` starts the highest cost first when it has no timings of its own (a fresh clone, as
#     in CI), so the long cases do not end up last beside an idle core.
# One `--list-test-cases` and one `--list-test-cases --test-suite=heavy` per suite (doctest_discover_tests'
# ADD_LABELS would start the suite once per test case, and its --test-case filter splits names at commas).
# Usage: cmake -DEXE=suite -DOUT=file.cmake -P heavy_labels.cmake (OUT is a TEST_INCLUDE_FILES script)
cmake_minimum_required(VERSION 3.18)  # if(IN_LIST)
get_filename_component(suite "${EXE}" NAME_WE)
function(list_cases out_var)
  execute_process(COMMAND "${EXE}" --list-test-cases ${ARGN} OUTPUT_VARIABLE out RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${EXE} --list-test-cases ${ARGN} failed (${rc})")
  endif()
  string(REPLACE "\n" ";" lines "${out}")
  set(cases "")
  foreach(line IN LISTS lines)
    if(line STREQUAL "" OR line MATCHES "^===+$" OR line MATCHES "^\\[doctest\\] ")
      continue()
    endif()
    list(APPEND cases "${line}")
  endforeach()
  set(${out_var} "${cases}" PARENT_SCOPE)
endfunction()
list_cases(all)
list_cases(heavy --test-suite=heavy)
set(script "")
foreach(line IN LISTS all)
  set(labels "${suite}")
  set(cost 1)
  if(line IN_LIST heavy)
    string(APPEND labels ";heavy")
    set(cost 10)
  endif()
  string(APPEND script "set_tests_properties([==[${line}]==] PROPERTIES LABELS \"${labels}\" COST ${cost})\n")
endforeach()
file(WRITE "${OUT}" "${script}")
