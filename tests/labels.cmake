# ctest labels of brume_tests' cases, set when ctest reads the discovered list
# (tests/CMakeLists.txt adds this file to TEST_INCLUDE_FILES after
# gtest_discover_tests' own file, whose brume_tests_TESTS it reads, and after
# labels_inputs.cmake, written at configure time, which names the python3 and
# the test sources). Each case gets every label whose expression its ctest
# name matches, and none of these labels otherwise:
#   gpu         the GPU backend's tests and sweeps (llvmpipe in CI)
#   study       the study's tests
#   effect_cli  the CLI suites of single effects, batch and sky: by the
#               naming rule of the tests, a suite or case that runs the CLI
#               has Cli in its name (CliFog, StereoCli, Sample.CliWrites...),
#               and the whole of Batch; the core CLI suite Cli itself is not
#               one (the sanitizer run's --ci form keeps it)
#   statistics  the camera rain's two statistical cases (8 seeds x 5
#               exposures of the splat the other CameraRain cases run under
#               the sanitizers too: 65 s of the ASan run's test time,
#               measured 2026-12-06 on a Zen 5); the --ci form leaves them
#               to the uninstrumented suite, as the TSan run does; and
#               snow's Monte Carlo of 2 x 100 000 beams and its camera's
#               Beer-Lambert case (0.45 s and 0.37 s in Release on a loaded
#               host: several seconds each under ASan)
# and the labels derived from the declarations and the sources:
#   part:NAME   the cases of the suites that part NAME's test files define
#               (brume_part(NAME FOLDER TESTS ...) in CMakeLists.txt, passed
#               in as brume_suite_parts, Suite=part): `ctest -L part:fog`
#               runs fog's; a suite two parts' files define has both labels
#   data        the cases that read the real data (BRUME_DATA_DIR, else
#               ../shared/data): those whose body uses data_dir, data_path,
#               have_data or BRUME_REQUIRE_DATA, directly or through what
#               their file (or a test header) defines with them
#               (tests/data_tests.py).
#               .ci/run runs them again with BRUME_DATA_DIR at an empty
#               folder, so that a test that fails without the data fails CI.
# The other ctest labels: install (install_consumer, tests/CMakeLists.txt),
# fuzz (the corpus replays, fuzz/CMakeLists.txt), and data on docs_examples
# and gallery_pictures_are_small (tests/CMakeLists.txt) and on python
# (python/CMakeLists.txt). scripts/test-sanitize.sh picks tests by these labels
# (ctest -LE); `ctest -N -L gpu` lists a label's.
set(brume_label_rules
  gpu "Gpu|GPU"
  study "Study"
  effect_cli "^([^.]*/)?Batch\\.|Cli([A-Z_./]|$)"
  statistics "^CameraRain\\.(EnergyIsIndependentOfExposure|FluctuationGoesAsTheInverseRootOfExposure)$|^LidarSnow\\.WallMovedShareAgreesWithAMonteCarloOfTheFootprintModel$|^CameraSnow\\.DrawnAndAnalyticTransmittanceIsBeerLambert$")

# The data cases, as Suite.Name (a TEST_P's ctest names add the instantiation
# before and the parameter after: Schemes/GaussianAccuracy.X/standard_2).
# At least this many discovered cases must get the label (56 cases in the
# sources, 84 ctest tests on 2026-12-05): fewer means the derivation broke.
set(brume_data_min 60)
set(brume_data_cases)
# A derivation that broke is a failing test (data_labels_derived), not an
# error that would stop every ctest run, whatever it selects.
function(brume_labels_failed why)
  string(REPLACE "'" "" why "${why}")
  string(REPLACE ";" " " why "${why}")
  add_test(data_labels_derived /bin/sh -c "echo 'tests/labels.cmake: ${why}'; exit 1")
  set_tests_properties(data_labels_derived PROPERTIES LABELS data)
endfunction()
if(brume_tests_TESTS)
  set(brume_data_args)
  foreach(brume_header IN LISTS brume_test_headers)
    list(APPEND brume_data_args --util ${brume_header})
  endforeach()
  execute_process(
    COMMAND ${brume_test_python} ${CMAKE_CURRENT_LIST_DIR}/data_tests.py gtest --min 1 ${brume_data_args}
            ${brume_test_sources}
    OUTPUT_VARIABLE brume_data_out ERROR_VARIABLE brume_data_err RESULT_VARIABLE brume_data_rc)
  if(NOT brume_data_rc EQUAL 0)
    brume_labels_failed("tests/data_tests.py failed (${brume_data_rc}): ${brume_data_err}")
    set(brume_data_out "")
  endif()
  string(STRIP "${brume_data_out}" brume_data_out)
  string(REPLACE "\n" ";" brume_data_cases "${brume_data_out}")
endif()

set(brume_data_labelled 0)
set(brume_data_matched)
foreach(brume_test IN LISTS brume_tests_TESTS)
  set(brume_labels)
  set(brume_rules ${brume_label_rules})
  while(brume_rules)
    list(POP_FRONT brume_rules brume_label brume_regex)
    if(brume_test MATCHES "${brume_regex}")
      list(APPEND brume_labels ${brume_label})
    endif()
  endwhile()
  if(brume_test MATCHES "^Cli\\.")
    list(REMOVE_ITEM brume_labels effect_cli)  # (the core CLI suite)
  endif()
  # Suite.Name of Suite.Name, Inst/Suite.Name and Inst/Suite.Name/param
  string(REGEX REPLACE "^[^./]*/" "" brume_case "${brume_test}")
  string(REGEX REPLACE "/.*$" "" brume_case "${brume_case}")
  string(REGEX REPLACE "[.].*$" "" brume_suite "${brume_case}")
  foreach(brume_pair IN LISTS brume_suite_parts)
    if(brume_pair MATCHES "^${brume_suite}=(.*)$")
      list(APPEND brume_labels "part:${CMAKE_MATCH_1}")
    endif()
  endforeach()
  list(FIND brume_data_cases "${brume_case}" brume_index)  # (ctest runs without CMP0057: no IN_LIST)
  if(brume_index GREATER -1)
    list(APPEND brume_labels data)
    list(APPEND brume_data_matched ${brume_case})
    math(EXPR brume_data_labelled "${brume_data_labelled} + 1")
  endif()
  if(brume_labels)
    set_tests_properties("${brume_test}" PROPERTIES LABELS "${brume_labels}")
  endif()
endforeach()

if(brume_tests_TESTS)
  if(brume_data_labelled LESS brume_data_min)
    brume_labels_failed("only ${brume_data_labelled} of brume_tests cases got the label data (at least "
      "${brume_data_min} expected): the derivation (tests/data_tests.py) or the name matching broke")
  endif()
  list(REMOVE_ITEM brume_data_cases ${brume_data_matched})
  if(brume_data_cases)
    message(WARNING "tests/labels.cmake: cases that read the data by their source but are not among brume_tests' "
      "discovered cases (rebuild brume_tests?): ${brume_data_cases}")
  endif()
endif()
