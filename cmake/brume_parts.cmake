# brume's library as a list of parts, one folder each (issues #37, #49):
#
#   brume_part(NAME FOLDER [HEADERS FILE...] [TESTS FILE...] [TSAN SUITE...] [THREADS_UNTESTED REASON])
#
# A part is everything in its folder (not its sub-folders; a sub-folder is a
# part of its own, declared by its own line, as aerial's insert and
# coefficients are):
#   *.cpp          compiled into libbrume (a file for the GPU backend guards
#                  itself with #if BRUME_HAVE_GPU, so both builds take the
#                  same list);
#   *.hpp, *.h     the part's private headers;
#   *.glsl         its shared GLSL topics: compiled as C++ through
#                  src/shared/prelude_cpp.h and embedded for the GPU passes
#                  that name them;
#   *.frag, *.vert its pass shaders, embedded.
# HEADERS names the public headers the part owns (under include/brume/):
# every include/brume/*.hpp is owned by exactly one part, or the configure
# fails; tests/check_layers.py reads them (generated/part_headers.txt) to
# find which layer each header lies in.
# TESTS names the test files the part owns (under tests/): they are compiled
# into brume_tests, and their GoogleTest cases get the ctest label
# part:NAME. Every tests/**/test_*.cpp is owned by exactly one part or
# named by brume_tests_outside_parts(REASON FILE...) (tests/CMakeLists.txt):
# a test file nobody declares fails the configure.
# A part whose files start threads (OpenMP's parallel/for/task, std::thread,
# std::async) is run under ThreadSanitizer (scripts/test-sanitize.sh) by its
# TESTS' suites, or by the suites TSAN names when only those reach its
# threads; THREADS_UNTESTED REASON exempts it, saying why (threads inside an
# uninstrumented library). A threaded part with neither fails the configure.
#
# Why a glob (CONFIGURE_DEPENDS) rather than a list of files: the folder is
# the declaration, so a file cannot sit in a family's folder without being
# built as part of it, and the next effect costs its folder and one line.
# CONFIGURE_DEPENDS re-globs at every build (a few milliseconds), so a new
# file is picked up without re-running cmake by hand. brume_generate_parts()
# checks the other way round: every source under src/ lies in a declared
# part's folder, or in a folder declared outside the library with
# brume_outside_parts(FOLDER REASON) (the codec module, a header-only
# interface).
#
# From these declarations, in declaration order (a topic may use those
# declared before it; within a part, topics in name order),
# brume_generate_parts() writes
#   generated/shared/topics_cpp.inc  the prelude's #include of every topic,
#   generated/gpu/topics.inc         the GPU context's table of topics,
#   generated/parts.txt              "NAME FOLDER" per line (for the checks in tests/),
#   generated/part_headers.txt       "NAME HEADER..." per line: each part's public headers (brume/x.hpp)
# and the list of GLSL files to embed (BRUME_SHADERS, name=path).
function(brume_part name folder)
  cmake_parse_arguments(PARSE_ARGV 2 arg "" "THREADS_UNTESTED" "HEADERS;TESTS;TSAN")
  if(arg_UNPARSED_ARGUMENTS)
    message(FATAL_ERROR "brume_part(${name} ${folder}): one folder per part; after it only HEADERS, TESTS, TSAN "
                        "and THREADS_UNTESTED (got ${arg_UNPARSED_ARGUMENTS})")
  endif()
  set(headers)
  foreach(h ${arg_HEADERS})
    if(NOT EXISTS ${PROJECT_SOURCE_DIR}/include/brume/${h})
      message(FATAL_ERROR "brume_part(${name} ${folder}): HEADERS ${h}: no such file include/brume/${h}")
    endif()
    list(APPEND headers brume/${h})
  endforeach()
  set(dir ${PROJECT_SOURCE_DIR}/${folder})
  if(NOT IS_DIRECTORY ${dir})
    message(FATAL_ERROR "brume_part(${name} ${folder}): no such folder")
  endif()
  file(GLOB sources CONFIGURE_DEPENDS RELATIVE ${PROJECT_SOURCE_DIR} ${dir}/*.cpp)
  file(GLOB topics CONFIGURE_DEPENDS RELATIVE ${PROJECT_SOURCE_DIR} ${dir}/*.glsl)
  file(GLOB shaders CONFIGURE_DEPENDS RELATIVE ${PROJECT_SOURCE_DIR} ${dir}/*.frag ${dir}/*.vert)
  list(SORT sources)
  list(SORT topics)
  list(SORT shaders)
  set(tests)
  foreach(t ${arg_TESTS})
    if(NOT EXISTS ${PROJECT_SOURCE_DIR}/tests/${t})
      message(FATAL_ERROR "brume_part(${name} ${folder}): TESTS ${t}: no such file tests/${t}")
    endif()
    list(APPEND tests tests/${t})
  endforeach()
  # Does the part start threads? (Its own files, headers included: a header's
  # OpenMP loop runs in whichever part includes it, and is counted there too.)
  file(GLOB own CONFIGURE_DEPENDS ${dir}/*.cpp ${dir}/*.hpp ${dir}/*.h)
  set(threads)
  foreach(f ${own})
    file(STRINGS ${f} hits REGEX "#[ \t]*pragma[ \t]+omp[ \t]+(parallel|for|task)|std::(j?thread|async)[^_a-z]")
    if(hits)
      file(RELATIVE_PATH rel ${PROJECT_SOURCE_DIR} ${f})
      list(APPEND threads ${rel})
    endif()
  endforeach()
  if(threads AND NOT tests AND NOT arg_THREADS_UNTESTED)
    list(GET threads 0 first)
    message(FATAL_ERROR "brume_part(${name} ${folder}): ${first} starts threads (OpenMP or std::thread), so the "
                        "part's tests run under ThreadSanitizer: name its test files with TESTS (or, when its "
                        "threads are a library's that TSan cannot see, say so with THREADS_UNTESTED \"reason\")")
  endif()
  if(arg_TSAN AND NOT threads)
    message(FATAL_ERROR "brume_part(${name} ${folder}): TSAN names suites for the part's threads, and no file of "
                        "${folder} starts any")
  endif()
  set_property(GLOBAL APPEND PROPERTY BRUME_PARTS "${name}=${folder}")
  string(REPLACE ";" "," headers_csv "${headers}")
  set_property(GLOBAL APPEND PROPERTY BRUME_PART_HEADERS "${name}=${headers_csv}")
  set_property(GLOBAL APPEND PROPERTY BRUME_PART_SOURCES ${sources})
  set_property(GLOBAL APPEND PROPERTY BRUME_PART_TOPICS ${topics})
  set_property(GLOBAL APPEND PROPERTY BRUME_PART_SHADERS ${shaders})
  set_property(GLOBAL APPEND PROPERTY BRUME_PART_TESTS ${tests})
  # name|test files|threaded (1/0)|TSan suites (empty: every suite of its tests)
  string(REPLACE ";" "," tests_csv "${tests}")
  string(REPLACE ";" "," tsan_csv "${arg_TSAN}")
  set(threaded 0)
  if(threads AND NOT arg_THREADS_UNTESTED)
    set(threaded 1)
  endif()
  set_property(GLOBAL APPEND PROPERTY BRUME_PART_TEST_DECLS "${name}|${tests_csv}|${threaded}|${tsan_csv}")
endfunction()

# A folder under src/ whose files are not libbrume's, with the reason.
function(brume_outside_parts folder reason)
  set_property(GLOBAL APPEND PROPERTY BRUME_OUTSIDE_PARTS ${folder})
endfunction()

# `item` (named `shown` in messages) owned by `part`, in the caller's lists
# `owned` and `owner_of`; owned already by another part: the configure fails,
# naming both and the declaration (`keyword`: HEADERS, TESTS).
macro(brume_own item shown keyword what part)
  list(FIND owned ${item} _brume_i)
  if(_brume_i GREATER -1)
    list(GET owner_of ${_brume_i} _brume_other)
    message(FATAL_ERROR "brume: ${shown} is in the ${keyword} of two parts, ${_brume_other} and ${part}: ${what} has "
                        "one owner")
  endif()
  list(APPEND owned ${item})
  list(APPEND owner_of ${part})
endmacro()

# Every item of the caller's list `items` is in its list `owned`, or the
# configure fails naming it (`prefix` before it) and the declaration to add.
macro(brume_require_owned items prefix keyword otherwise)
  foreach(_brume_x ${${items}})
    if(NOT _brume_x IN_LIST owned)
      message(FATAL_ERROR "brume: ${prefix}${_brume_x} belongs to no part: add it to its part's ${keyword} in "
                          "CMakeLists.txt (brume_part(NAME FOLDER ${keyword} ...))${otherwise}")
    endif()
  endforeach()
endmacro()

# Writes `content` to `path` only when it differs (no rebuild otherwise).
function(brume_write_if_different path content)
  file(WRITE "${path}.tmp" "${content}")
  configure_file("${path}.tmp" "${path}" COPYONLY)
endfunction()

# The generated lists, and in the caller's scope BRUME_PART_SOURCES (the
# library's sources) and BRUME_SHADERS (name=path of every GLSL file to embed).
function(brume_generate_parts gen_dir)
  get_property(parts GLOBAL PROPERTY BRUME_PARTS)
  get_property(sources GLOBAL PROPERTY BRUME_PART_SOURCES)
  get_property(topics GLOBAL PROPERTY BRUME_PART_TOPICS)
  get_property(shaders GLOBAL PROPERTY BRUME_PART_SHADERS)
  get_property(outside GLOBAL PROPERTY BRUME_OUTSIDE_PARTS)
  # Every source file under src/ belongs to exactly one declared folder.
  set(folders)
  set(listing "")
  foreach(p ${parts})
    string(REPLACE "=" ";" kv "${p}")
    list(GET kv 0 n)
    list(GET kv 1 f)
    if(f IN_LIST folders)
      message(FATAL_ERROR "brume: the folder ${f} is declared twice (brume_part ${n})")
    endif()
    list(APPEND folders ${f})
    string(APPEND listing "${n} ${f}\n")
  endforeach()
  file(GLOB_RECURSE all CONFIGURE_DEPENDS RELATIVE ${PROJECT_SOURCE_DIR} ${PROJECT_SOURCE_DIR}/src/*.cpp
       ${PROJECT_SOURCE_DIR}/src/*.hpp ${PROJECT_SOURCE_DIR}/src/*.h ${PROJECT_SOURCE_DIR}/src/*.glsl
       ${PROJECT_SOURCE_DIR}/src/*.frag ${PROJECT_SOURCE_DIR}/src/*.vert)
  foreach(f ${all})
    get_filename_component(d ${f} DIRECTORY)
    if(NOT d IN_LIST folders AND NOT d IN_LIST outside)
      message(FATAL_ERROR "brume: ${f} lies in ${d}, which no brume_part() in CMakeLists.txt declares: "
                          "add `brume_part(NAME ${d})`, or move the file into its family's folder")
    endif()
  endforeach()
  brume_write_if_different("${gen_dir}/parts.txt" "${listing}")
  # Every public header is one part's.
  get_property(part_headers GLOBAL PROPERTY BRUME_PART_HEADERS)
  set(owned)
  set(owner_of)
  set(listing "")
  foreach(p ${part_headers})
    string(REPLACE "=" ";" kv "${p}")
    list(GET kv 0 n)
    set(hs)
    list(LENGTH kv len)
    if(len GREATER 1)
      list(GET kv 1 hs)
      string(REPLACE "," ";" hs "${hs}")
    endif()
    foreach(h ${hs})
      brume_own(${h} include/${h} HEADERS "a header" ${n})
    endforeach()
    string(REPLACE ";" " " hs "${hs}")
    string(STRIP "${n} ${hs}" line)
    string(APPEND listing "${line}\n")
  endforeach()
  file(GLOB public CONFIGURE_DEPENDS RELATIVE ${PROJECT_SOURCE_DIR}/include ${PROJECT_SOURCE_DIR}/include/brume/*.hpp)
  brume_require_owned(public "include/" HEADERS "")
  brume_write_if_different("${gen_dir}/part_headers.txt" "${listing}")
  set(header "// Generated by cmake/brume_parts.cmake from the brume_part() declarations in CMakeLists.txt. Do not edit.\n")
  set(cpp "${header}")
  set(gpu "${header}")
  set(embed)
  foreach(t ${topics})
    get_filename_component(n ${t} NAME_WE)
    string(REGEX REPLACE "^src/" "" inc "${t}")
    string(APPEND cpp "#include \"${inc}\"\n")
    string(APPEND gpu "{\"${n}\", shaders::${n}_glsl},\n")
    list(APPEND embed "${n}_glsl=${PROJECT_SOURCE_DIR}/${t}")
  endforeach()
  brume_write_if_different("${gen_dir}/shared/topics_cpp.inc" "${cpp}")
  brume_write_if_different("${gen_dir}/gpu/topics.inc" "${gpu}")
  foreach(s ${shaders})
    get_filename_component(n ${s} NAME)
    string(REPLACE "." "_" n "${n}")
    list(APPEND embed "${n}=${PROJECT_SOURCE_DIR}/${s}")
  endforeach()
  set(BRUME_PART_SOURCES ${sources} PARENT_SCOPE)
  set(BRUME_SHADERS ${embed} PARENT_SCOPE)
endfunction()

# brume_embed(HEADER NAMESPACE COMMENT FILES_VAR name=path...): the files as
# string constants `name` in HEADER (cmake/embed_shaders.cmake), remade when
# one changes; FILES_VAR gets their paths. The GPU passes' GLSL and brume
# view's page and modules.
function(brume_embed header namespace comment files_var)
  set(files)
  foreach(pair ${ARGN})
    string(REPLACE "=" ";" kv "${pair}")
    list(GET kv 1 path)
    list(APPEND files ${path})
  endforeach()
  string(REPLACE ";" "|" arg "${ARGN}")
  add_custom_command(OUTPUT ${header}
    COMMAND ${CMAKE_COMMAND} "-DOUT=${header}" "-DINPUTS=${arg}" "-DNAMESPACE=${namespace}"
            -P ${PROJECT_SOURCE_DIR}/cmake/embed_shaders.cmake
    DEPENDS ${files} ${PROJECT_SOURCE_DIR}/cmake/embed_shaders.cmake
    COMMENT "${comment}" VERBATIM)
  set(${files_var} ${files} PARENT_SCOPE)
endfunction()

# The tests, from the parts' TESTS (called by tests/CMakeLists.txt with the
# test files that belong to no part, each list with its reason given there):
# every tests/**/test_*.cpp owned exactly once. In the caller's scope
# BRUME_TEST_SOURCES (the files of brume_tests, absolute) and
# BRUME_TEST_SUITE_PARTS ("Suite=part" for every suite of every part's files,
# for the part:NAME labels). Writes gen_dir/tsan_filter.txt, the gtest filter
# of scripts/test-sanitize.sh's ThreadSanitizer run: the suites of every
# threaded part (or its TSAN suites), less the cases in `tsan_leave_out`
# (gtest patterns, given with their reasons by the caller).
function(brume_part_tests gen_dir outside tsan_leave_out)
  get_property(decls GLOBAL PROPERTY BRUME_PART_TEST_DECLS)
  set(owned)
  set(owner_of)
  set(suite_parts)
  set(tsan)
  foreach(d ${decls})
    string(REPLACE "|" ";" f "${d}")
    list(GET f 0 name)
    list(GET f 1 tests)
    list(GET f 2 threaded)
    list(GET f 3 tsan_suites)
    string(REPLACE "," ";" tests "${tests}")
    string(REPLACE "," ";" tsan_suites "${tsan_suites}")
    set(part_suites)
    foreach(t ${tests})
      brume_own(${t} ${t} TESTS "a test file" ${name})
      file(STRINGS ${PROJECT_SOURCE_DIR}/${t} lines REGEX "^[ \t]*(TYPED_)?TEST(_F|_P)?[ \t]*\\([ \t]*[A-Za-z_0-9]+")
      foreach(l ${lines})
        string(REGEX REPLACE "^[ \t]*(TYPED_)?TEST(_F|_P)?[ \t]*\\([ \t]*([A-Za-z_0-9]+).*" "\\3" suite "${l}")
        list(APPEND part_suites ${suite})
      endforeach()
    endforeach()
    list(REMOVE_DUPLICATES part_suites)
    foreach(s ${part_suites})
      list(APPEND suite_parts "${s}=${name}")
    endforeach()
    if(threaded)
      if(tsan_suites)
        foreach(s ${tsan_suites})
          if(NOT s IN_LIST part_suites)
            message(FATAL_ERROR "brume_part(${name}): TSAN ${s} is no suite of its TESTS (${part_suites})")
          endif()
        endforeach()
        list(APPEND tsan ${tsan_suites})
      else()
        list(APPEND tsan ${part_suites})
      endif()
    endif()
  endforeach()
  foreach(t ${outside})
    if(t IN_LIST owned)
      message(FATAL_ERROR "brume: ${t} is owned by a part and also listed outside the parts")
    endif()
    list(APPEND owned ${t})
  endforeach()
  file(GLOB_RECURSE all CONFIGURE_DEPENDS RELATIVE ${PROJECT_SOURCE_DIR} ${PROJECT_SOURCE_DIR}/tests/test_*.cpp)
  brume_require_owned(all "" TESTS ", or to the files outside the parts in tests/CMakeLists.txt")
  # gtest matches a parameterised case by its full name, Inst/Suite.Name/param: both forms.
  list(REMOVE_DUPLICATES tsan)
  list(SORT tsan)
  set(positive)
  foreach(s ${tsan})
    list(APPEND positive "${s}.*" "*/${s}.*")
  endforeach()
  string(REPLACE ";" ":" positive "${positive}")
  string(REPLACE ";" ":" negative "${tsan_leave_out}")
  brume_write_if_different("${gen_dir}/tsan_filter.txt" "${positive}-${negative}\n")
  list(TRANSFORM owned PREPEND ${PROJECT_SOURCE_DIR}/)
  set(BRUME_TEST_SOURCES ${owned} PARENT_SCOPE)
  set(BRUME_TEST_SUITE_PARTS ${suite_parts} PARENT_SCOPE)
endfunction()
