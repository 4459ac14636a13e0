# brume_part()'s folder rule (cmake/brume_parts.cmake), on scratch trees:
# a source in a folder no part declares fails the configure with a message
# naming the file and the line to add; a declared tree generates its lists
# (topics in declaration order, sub-folders as parts of their own); the
# parts' public headers and tests: a header or test file no part owns, or
# owned twice, and a part that starts threads without tests or a stated
# exemption fail the configure; the ThreadSanitizer filter is the threaded
# parts' suites.
#   cmake -DPARTS=cmake/brume_parts.cmake -DWORK=DIR -P check_parts.cmake
file(REMOVE_RECURSE ${WORK})
# A scratch project in `d` with these declarations and the trailing lines
# `tail`, configured: in the caller's caller (scratch, scratch_tests) rc, err
# (CMake's line wrapping undone) and dir.
function(configure_scratch d declarations tail)
  file(WRITE ${d}/CMakeLists.txt "cmake_minimum_required(VERSION 3.20)\nproject(scratch LANGUAGES NONE)\n"
       "include(${PARTS})\n${declarations}\nbrume_generate_parts(\${CMAKE_BINARY_DIR}/generated)\n${tail}")
  execute_process(COMMAND ${CMAKE_COMMAND} -S ${d} -B ${d}/build RESULT_VARIABLE rc OUTPUT_VARIABLE out
                  ERROR_VARIABLE err)
  string(REGEX REPLACE "[ \n]+" " " err "${err}")  # CMake wraps its messages
  set(rc ${rc} PARENT_SCOPE)
  set(err "${err}" PARENT_SCOPE)
endfunction()
function(scratch name declarations)
  set(d ${WORK}/${name})
  file(WRITE ${d}/src/core/image.cpp "")
  file(WRITE ${d}/src/effects/mist/mist.cpp "")
  file(WRITE ${d}/src/effects/mist/mist_math.glsl "")
  file(WRITE ${d}/src/effects/mist/mist_apply.frag "")
  file(WRITE ${d}/src/effects/mist/drops/drops.cpp "")
  file(WRITE ${d}/src/effects/mist/drops/drops_math.glsl "")
  file(WRITE ${d}/src/tools/codec.cpp "")
  configure_scratch(${d} "${declarations}"
    "file(WRITE \${CMAKE_BINARY_DIR}/sources.txt \"\${BRUME_PART_SOURCES}|\${BRUME_SHADERS}\")\n")
  set(rc ${rc} PARENT_SCOPE)
  set(err "${err}" PARENT_SCOPE)
  set(dir ${d} PARENT_SCOPE)
endfunction()

set(all "brume_part(core src/core)\nbrume_part(mist src/effects/mist)\nbrume_part(drops src/effects/mist/drops)\n")
# A sub-folder is not its parent's: without its own line, the configure fails.
scratch(missing "brume_part(core src/core)\nbrume_part(mist src/effects/mist)\nbrume_outside_parts(src/tools \"a module\")")
if(rc EQUAL 0 OR NOT err MATCHES "src/effects/mist/drops/drops.cpp lies in src/effects/mist/drops, which no brume_part")
  message(FATAL_ERROR "an undeclared folder was accepted (rc ${rc}): ${err}")
endif()
# A folder declared outside the library must be declared too.
scratch(outside "${all}")
if(rc EQUAL 0 OR NOT err MATCHES "src/tools/codec.cpp lies in src/tools")
  message(FATAL_ERROR "a file outside every part was accepted (rc ${rc}): ${err}")
endif()
# One folder, one part.
scratch(twice "${all}brume_part(again src/core)\nbrume_outside_parts(src/tools \"a module\")")
if(rc EQUAL 0 OR NOT err MATCHES "src/core is declared twice")
  message(FATAL_ERROR "a folder declared twice was accepted (rc ${rc}): ${err}")
endif()
# Everything declared: the lists, in declaration order.
scratch(complete "${all}brume_outside_parts(src/tools \"a module\")")
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "a complete declaration failed: ${err}")
endif()
file(READ ${dir}/build/generated/shared/topics_cpp.inc topics)
if(NOT topics MATCHES "#include \"effects/mist/mist_math.glsl\"\n#include \"effects/mist/drops/drops_math.glsl\"\n$")
  message(FATAL_ERROR "topics not in declaration order: ${topics}")
endif()
file(READ ${dir}/build/generated/parts.txt parts)
if(NOT parts STREQUAL "core src/core\nmist src/effects/mist\ndrops src/effects/mist/drops\n")
  message(FATAL_ERROR "parts.txt: ${parts}")
endif()
file(READ ${dir}/build/sources.txt sources)
if(NOT sources MATCHES "^src/core/image.cpp;src/effects/mist/mist.cpp;src/effects/mist/drops/drops.cpp[|]" OR
   NOT sources MATCHES "mist_apply_frag=[^;]*/src/effects/mist/mist_apply.frag" OR sources MATCHES "codec")
  message(FATAL_ERROR "sources and shaders: ${sources}")
endif()

# The public headers: each one part's (HEADERS), listed in part_headers.txt.
# A scratch tree with two public headers and these declarations, configured:
# it fails with a message matching `expect`, or succeeds when `expect` is "".
function(headers_case name declarations expect)
  set(d ${WORK}/headers-${name})
  file(WRITE ${d}/src/core/image.cpp "")
  file(WRITE ${d}/src/effects/mist/mist.cpp "")
  file(WRITE ${d}/include/brume/image.hpp "")
  file(WRITE ${d}/include/brume/mist.hpp "")
  configure_scratch(${d} "${declarations}" "")
  if(expect AND (rc EQUAL 0 OR NOT err MATCHES "${expect}"))
    message(FATAL_ERROR "headers ${name}: accepted, or not refused with '${expect}' (rc ${rc}): ${err}")
  elseif(NOT expect AND NOT rc EQUAL 0)
    message(FATAL_ERROR "headers ${name}: a declared tree failed: ${err}")
  endif()
  set(d ${d} PARENT_SCOPE)
endfunction()
headers_case(unowned "brume_part(core src/core HEADERS image.hpp)\nbrume_part(mist src/effects/mist)"
             "include/brume/mist.hpp belongs to no part")
headers_case(twice "brume_part(core src/core HEADERS image.hpp mist.hpp)\nbrume_part(mist src/effects/mist HEADERS mist.hpp)"
             "include/brume/mist.hpp is in the HEADERS of two parts, core and mist")
headers_case(owned "brume_part(core src/core HEADERS image.hpp)\nbrume_part(mist src/effects/mist HEADERS mist.hpp)" "")
file(READ ${d}/build/generated/part_headers.txt headers)
if(NOT headers STREQUAL "core brume/image.hpp\nmist brume/mist.hpp\n")
  message(FATAL_ERROR "part_headers.txt: ${headers}")
endif()

# The tests: a threaded part (an OpenMP loop in mist.cpp) and its test files.
function(scratch_tests name declarations)
  set(d ${WORK}/tests-${name})
  file(WRITE ${d}/src/core/image.cpp "")
  file(WRITE ${d}/src/effects/mist/mist.cpp "void f(int n) {\n#pragma omp parallel for\n  for (int i = 0; i < n; ++i) {}\n}\n")
  file(WRITE ${d}/tests/test_core.cpp "TEST(Image, Sizes) {}\n")
  file(WRITE ${d}/tests/test_mist.cpp "TEST(Mist, Extinction) {}\nTEST_F(MistCli, Flags) {}\n  TEST_P( MistSweep , Rates) {}\n")
  configure_scratch(${d} "${declarations}"
    "brume_part_tests(\${CMAKE_BINARY_DIR}/generated \"\" \"*Cli*\")\nfile(WRITE \${CMAKE_BINARY_DIR}/tests.txt \"\${BRUME_TEST_SOURCES}|\${BRUME_TEST_SUITE_PARTS}\")\n")
  set(rc ${rc} PARENT_SCOPE)
  set(err "${err}" PARENT_SCOPE)
  set(dir ${d} PARENT_SCOPE)
endfunction()
set(core "brume_part(core src/core TESTS test_core.cpp)\n")
scratch_tests(untested "${core}brume_part(mist src/effects/mist)")
if(rc EQUAL 0 OR NOT err MATCHES "src/effects/mist/mist.cpp starts threads")
  message(FATAL_ERROR "a threaded part without tests was accepted (rc ${rc}): ${err}")
endif()
scratch_tests(unowned "brume_part(core src/core)\nbrume_part(mist src/effects/mist TESTS test_mist.cpp)")
if(rc EQUAL 0 OR NOT err MATCHES "tests/test_core.cpp belongs to no part")
  message(FATAL_ERROR "a test file no part owns was accepted (rc ${rc}): ${err}")
endif()
scratch_tests(twice "${core}brume_part(mist src/effects/mist TESTS test_mist.cpp test_core.cpp)")
if(rc EQUAL 0 OR NOT err MATCHES "tests/test_core.cpp is in the TESTS of two parts, core and mist")
  message(FATAL_ERROR "a test file owned twice was accepted (rc ${rc}): ${err}")
endif()
scratch_tests(nosuite "${core}brume_part(mist src/effects/mist TESTS test_mist.cpp TSAN Fog)")
if(rc EQUAL 0 OR NOT err MATCHES "TSAN Fog is no suite of its TESTS")
  message(FATAL_ERROR "a TSAN suite the part does not define was accepted (rc ${rc}): ${err}")
endif()
scratch_tests(exempt "${core}brume_part(mist src/effects/mist THREADS_UNTESTED \"a library's pool\")")
if(rc EQUAL 0 OR NOT err MATCHES "tests/test_mist.cpp belongs to no part")
  message(FATAL_ERROR "an exempt part's unowned test file was accepted (rc ${rc}): ${err}")
endif()
scratch_tests(tested "${core}brume_part(mist src/effects/mist TESTS test_mist.cpp)")
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "a declared tree failed: ${err}")
endif()
file(READ ${dir}/build/generated/tsan_filter.txt filter)
if(NOT filter STREQUAL "Mist.*:*/Mist.*:MistCli.*:*/MistCli.*:MistSweep.*:*/MistSweep.*-*Cli*\n")
  message(FATAL_ERROR "tsan_filter.txt: ${filter}")
endif()
file(READ ${dir}/build/tests.txt tests)
if(NOT tests MATCHES "^[^|]*/tests/test_core.cpp;[^|]*/tests/test_mist.cpp[|]Image=core;Mist=mist;MistCli=mist;MistSweep=mist$")
  message(FATAL_ERROR "test sources and suites: ${tests}")
endif()
message(STATUS "check_parts: undeclared folders refused, declared ones listed in order; public headers and test "
               "files owned once, threaded parts tested, the TSan filter their suites")
