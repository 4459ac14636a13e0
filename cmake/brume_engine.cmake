# The diffusion engine's per-file compile options, set by the library's build
# (CMakeLists.txt) and by the engine-only build (tests/engine/, the aarch64
# cross build): the same options in both, so that the targets tested under
# qemu are compiled as the library compiles them.
#
# The fast diffusion path (diffusion_fast.cpp, the schedule and set-up, and
# diffusion_fast_kernels.cpp, its row kernels: both need every option below,
# and like every file with options of its own each is compiled alone, outside
# the unity build) never reads errno: without -fmath-errno, sqrt and
# floor in its per-pixel offset loops vectorise, and without -ftrapping-math
# GCC if-converts the min/harmonic edge-rate selects of the space-variant
# weight loop, which then vectorises too (IEEE results unchanged). Its
# Highway targets AVX2 and AVX-512 enable FMA, and GCC 12 contracts a*b+c in
# C++ even in ISO mode: -ffp-contract=off keeps every target on the
# reference's operation order (the same holds for the binary16 rows and the
# fog's row, which Highway compiles for the same targets).
# -Wno-psabi: the set-up's e^x and ln x (diffusion_setup_math.hpp) pass
# eight-float vectors between inlined helpers, which GCC notes as an ABI
# change for AVX vectors; no such function crosses a library boundary.
# `root`: the repository's root (the files are named from it).
function(brume_engine_source_options root)
  set_source_files_properties(${root}/src/diffusion/diffusion_fast.cpp ${root}/src/diffusion/diffusion_fast_kernels.cpp
    PROPERTIES COMPILE_OPTIONS "-fno-math-errno;-fno-trapping-math;-ffp-contract=off;-Wno-psabi")
  set_source_files_properties(${root}/src/diffusion/diffusion_fast_f16.cpp
    PROPERTIES COMPILE_OPTIONS "-fno-math-errno;-ffp-contract=off;-Wno-psabi")  # -Wno-psabi: see diffusion_fast.cpp above
  # hwy/foreach_target.h includes the file itself again per target: never inside a unity bundle.
  set_source_files_properties(${root}/src/diffusion/diffusion_fast_kernels.cpp ${root}/src/diffusion/diffusion_fast_f16.cpp
    ${root}/src/core/simd.cpp PROPERTIES SKIP_UNITY_BUILD_INCLUSION ON)
endfunction()
