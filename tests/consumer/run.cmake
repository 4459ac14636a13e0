# ctest `install_consumer`: install brume into a prefix under the build tree,
# then configure, build and run tests/consumer against it (offline; only the
# packages brume itself was built with). Variables: BUILD_DIR, SOURCE_DIR,
# WORK_DIR, CXX, BUILD_TYPE, GENERATOR.
file(REMOVE_RECURSE "${WORK_DIR}")
set(prefix "${WORK_DIR}/prefix")

function(step what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "install_consumer: ${what} failed (${rc}):\n${out}\n${err}")
  endif()
  message(STATUS "${what}: ok")
  set(last_out "${out}" PARENT_SCOPE)
endfunction()

step("install" ${CMAKE_COMMAND} --install "${BUILD_DIR}" --prefix "${prefix}")
foreach(f include/brume/image.hpp include/brume/diffusion.hpp)
  if(NOT EXISTS "${prefix}/${f}")
    message(FATAL_ERROR "install_consumer: ${f} was not installed")
  endif()
endforeach()
# Fixtures and study code stay out of the installed package.
foreach(f include/brume/demo_scene.hpp include/brume/peers.hpp)
  if(EXISTS "${prefix}/${f}")
    message(FATAL_ERROR "install_consumer: ${f} must not be installed")
  endif()
endforeach()
step("configure consumer" ${CMAKE_COMMAND} -S "${SOURCE_DIR}" -B "${WORK_DIR}/build" -G "${GENERATOR}"
     "-DCMAKE_PREFIX_PATH=${prefix}" "-DCMAKE_CXX_COMPILER=${CXX}" "-DCMAKE_BUILD_TYPE=${BUILD_TYPE}")
step("build consumer" ${CMAKE_COMMAND} --build "${WORK_DIR}/build" -j2)
file(GLOB_RECURSE codec "${prefix}/lib*/brume/brume_codec.so")
if(NOT codec)
  message(FATAL_ERROR "install_consumer: <libdir>/brume/brume_codec.so was not installed")
endif()
# The prefix is not the one brume was configured for, so the installed
# module is named by BRUME_CODEC_MODULE, as a relocated install's user would.
step("run consumer" ${CMAKE_COMMAND} -E env "BRUME_CODEC_MODULE=${codec}"
     "${WORK_DIR}/build/brume_consumer" "${WORK_DIR}/roundtrip.png")
message(STATUS "${last_out}")
