# ctest labels of brume_tests' cases, set when ctest reads the discovered list
# (tests/CMakeLists.txt adds this file to TEST_INCLUDE_FILES after
# gtest_discover_tests' own file, whose brume_tests_TESTS it reads). Each case
# gets every label whose expression its ctest name matches, and none of these
# labels otherwise:
#   gpu         the GPU backend's tests and sweeps (llvmpipe in CI)
#   study       the study's tests
#   effect_cli  the CLI suites of single effects, batch and sky
# The other ctest labels: install (install_consumer, tests/CMakeLists.txt),
# fuzz (the corpus replays, fuzz/CMakeLists.txt). scripts/test-sanitize.sh
# picks tests by these labels (ctest -LE); `ctest -N -L gpu` lists a label's.
set(brume_label_rules
  gpu "Gpu|GPU"
  study "Study"
  effect_cli "Batch|SkyCli|CliAerial|CliInsert|CliFog|CliDof|CliChain|Sample\\.Cli")
foreach(brume_test IN LISTS brume_tests_TESTS)
  set(brume_labels)
  set(brume_rules ${brume_label_rules})
  while(brume_rules)
    list(POP_FRONT brume_rules brume_label brume_regex)
    if(brume_test MATCHES "${brume_regex}")
      list(APPEND brume_labels ${brume_label})
    endif()
  endwhile()
  if(brume_labels)
    set_tests_properties("${brume_test}" PROPERTIES LABELS "${brume_labels}")
  endif()
endforeach()
