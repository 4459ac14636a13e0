# brume_part()'s folder rule (cmake/brume_parts.cmake), on scratch trees:
# a source in a folder no part declares fails the configure with a message
# naming the file and the line to add; a declared tree generates its lists
# (topics in declaration order, sub-folders as parts of their own).
#   cmake -DPARTS=cmake/brume_parts.cmake -DWORK=DIR -P check_parts.cmake
file(REMOVE_RECURSE ${WORK})
function(scratch name declarations)
  set(d ${WORK}/${name})
  file(WRITE ${d}/src/core/image.cpp "")
  file(WRITE ${d}/src/effects/mist/mist.cpp "")
  file(WRITE ${d}/src/effects/mist/mist_math.glsl "")
  file(WRITE ${d}/src/effects/mist/mist_apply.frag "")
  file(WRITE ${d}/src/effects/mist/drops/drops.cpp "")
  file(WRITE ${d}/src/effects/mist/drops/drops_math.glsl "")
  file(WRITE ${d}/src/tools/codec.cpp "")
  file(WRITE ${d}/CMakeLists.txt "cmake_minimum_required(VERSION 3.20)\nproject(scratch LANGUAGES NONE)\n"
       "include(${PARTS})\n${declarations}\nbrume_generate_parts(\${CMAKE_BINARY_DIR}/generated)\n"
       "file(WRITE \${CMAKE_BINARY_DIR}/sources.txt \"\${BRUME_PART_SOURCES}|\${BRUME_SHADERS}\")\n")
  execute_process(COMMAND ${CMAKE_COMMAND} -S ${d} -B ${d}/build RESULT_VARIABLE rc OUTPUT_VARIABLE out
                  ERROR_VARIABLE err)
  set(rc ${rc} PARENT_SCOPE)
  string(REGEX REPLACE "[ \n]+" " " err "${err}")  # CMake wraps its messages
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
message(STATUS "check_parts: undeclared folders refused, declared ones listed in order")
