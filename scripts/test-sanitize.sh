#!/usr/bin/env bash
# The test suite under sanitizers (issue #15): the README's second test
# command, run by .ci/run after scripts/test.sh.
#  1. AddressSanitizer + UndefinedBehaviorSanitizer (clang-14, -O1): the
#     library, the CLI the tests run, the test suite (GPU tests included, on
#     Mesa llvmpipe) and the fuzz targets, which replay their committed
#     corpora (fuzz/corpus). Any report fails the run.
#  2. ThreadSanitizer on the multithreaded CPU paths (OpenMP): clang-14 with
#     LLVM's libomp and its Archer tool, which tells TSan about OpenMP's own
#     barriers and tasks (with GCC's libgomp, TSan sees none and reports
#     false races). A gtest filter, derived from the parts' declarations,
#     picks the tests that run threaded code.
# Cost on 2 cores (a clean clone; .ci/run runs the whole script), unity
# builds: AMD EPYC (Zen 4), 2026-12-01: ASan+UBSan build 277-295 s (490 s
# file by file), its 342 tests 528-565 s; TSan build 143-146 s (255 s file by
# file), its suites 35-37 s. Intel Xeon family 6 model 207, 2026-12-04: ASan+UBSan
# build 235 s, its 381 tests (fuzz corpora included) 247 s; TSan build 113 s,
# its suites 46 s; with the derived set (270 cases: the suites of every
# threaded part), AMD EPYC family 26 (Zen 5), 2026-12-05, two other builds
# running: TSan build 102 s, its suites 231 s
# (docs/reliability.md). Options: --asan-only, --tsan-only, and --ci, a
# shorter form: every test under ASan except those that mostly re-run the CLI
# or the GPU passes (CI_SKIP_LABELS below; 297 tests on 2026-12-04, plus the fuzz replays),
# then TSan.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
jobs=$(nproc)
run_asan=1 run_tsan=1
# ctest labels (tests/labels.cmake, tests/CMakeLists.txt) of the tests the
# ASan run leaves out.
skip_labels='^install$'
# --ci leaves out too: the GPU tests and sweeps (llvmpipe under an instrumented
# host: ~160 s), the study, and the CLI suites of single effects, batch and
# sky, whose parsers and files the fuzz corpora, Cli.* and Reliability.* also
# reach under ASan; and the camera rain's two statistical cases (label
# statistics: 65 s of test time, the same splat the other CameraRain cases run).
CI_SKIP_LABELS='^(install|gpu|study|effect_cli|statistics)$'
case "${1:-}" in
  --asan-only) run_tsan=0 ;;
  --tsan-only) run_asan=0 ;;
  --ci) skip_labels="$CI_SKIP_LABELS" ;;
  "") ;;
  *) echo "usage: $0 [--asan-only|--tsan-only|--ci]" >&2; exit 2 ;;
esac
# -O1 keeps the instrumented build and run fast with readable stacks; no
# benchmarks, no Python module (its interpreter is not instrumented).
# A unity build (CMake joins each target's sources, eight to a translation
# unit): the instrumented compiles are mostly the same headers parsed and the
# same templates (nlohmann::json, OpenImageIO, gtest) instantiated and
# instrumented again in every file, so joining them is what makes both
# sanitizer builds fit CI (measured in docs/reliability.md). It needs every
# file-local name to be unique across a target's files; this build is what
# checks that.
common=(-DCMAKE_CXX_COMPILER=clang++-14 -DCMAKE_BUILD_TYPE=RelWithDebInfo
        "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -gline-tables-only"
        -DCMAKE_UNITY_BUILD=ON
        -DBRUME_BUILD_BENCH=OFF -DBRUME_PYTHON=OFF)
if command -v ccache >/dev/null; then common+=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
supp="$PWD/scripts/sanitize/lsan.supp"

if [ "$run_asan" = 1 ]; then
  t0=$(date +%s)
  cmake -S . -B build-asan "${common[@]}" -DBRUME_SANITIZE=address,undefined -DBRUME_FUZZ=ON -DBRUME_FUZZ_COVERAGE=OFF
  # detect_leaks: on, with Debian's libraries' leaks suppressed (see the
  # file); set before the build, whose test discovery runs the test binary.
  # intercept_tls_get_addr=0: LLVM 14's __tls_get_addr interceptor takes a
  # dynamic TLS block that malloc happens to place 16 bytes past a page
  # boundary for a glibc <= 2.24 block with a header, and reads the two words
  # before it as that block's bounds; LSan's tracer then faults on them at
  # exit ("Tracer caught signal 11", "LeakSanitizer has encountered a fatal
  # error"), on no leak, in whichever process drew that address. Dynamic TLS
  # appeared with the dlopen()ed OpenImageIO module (brume_codec.so and its
  # libraries); CI failed this way on three batch tests on 2026-12-02. Fixed
  # upstream after LLVM 16. Without the interceptor LSan still reaches those
  # blocks as heap objects through the threads' DTV.
  export ASAN_OPTIONS="detect_leaks=1:intercept_tls_get_addr=0"
  export LSAN_OPTIONS="suppressions=$supp:print_suppressions=0"
  export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
  cmake --build build-asan -j"$jobs"
  t1=$(date +%s)
  # Mesa's llvmpipe driver (swrast_dri.so) is dlopen()ed for the first EGL
  # display and dlclose()d again when the display is terminated. Its caches
  # (shader variants, ~56-byte blocks that point at each other) stay
  # allocated, and once the driver's data segment is unmapped LSan no longer
  # sees the pointers that held them: every GPU test then reports an
  # "indirect leak" from "<unknown module>", which no suppression can name.
  # Preloading the driver keeps it mapped for the life of the process (the
  # loader's dlclose only drops a reference), so those blocks stay reachable
  # and are not leaks; a real leak in brume's GPU code is still reported.
  # Child processes (the CLI the tests run) inherit it; set after the build
  # so that the compilers do not load the driver.
  dri=/usr/lib/x86_64-linux-gnu/dri/swrast_dri.so
  if [ -e "$dri" ]; then export LD_PRELOAD="$dri${LD_PRELOAD:+:$LD_PRELOAD}"; fi
  # install_consumer builds an uninstrumented project against the
  # instrumented static library: not meaningful here (scripts/test.sh runs it).
  ctest --test-dir build-asan --output-on-failure -j"$jobs" -LE "$skip_labels"
  t2=$(date +%s)
  echo "test-sanitize: ASan+UBSan build $((t1 - t0)) s, tests and fuzz regression $((t2 - t1)) s"
  unset ASAN_OPTIONS LSAN_OPTIONS UBSAN_OPTIONS LD_PRELOAD
fi

if [ "$run_tsan" = 1 ]; then
  t0=$(date +%s)
  cmake -S . -B build-tsan "${common[@]}" -DBRUME_SANITIZE=thread
  # The CLI too: tests of these suites that check a record's replay run it.
  cmake --build build-tsan -j"$jobs" --target brume_tests brume_cli
  t1=$(date +%s)
  archer=$(ls /usr/lib/llvm-14/lib/libarcher.so)
  # The threaded code, at four threads: the suites of every part whose files
  # start threads (OpenMP loops, batch's workers, brume view's HTTP front),
  # as the parts declare them (brume_part(... TESTS/TSAN) in CMakeLists.txt),
  # less the GPU and CLI cases; the configure writes the filter
  # (brume_part_tests in cmake/brume_parts.cmake; the cases left out and
  # why: tests/CMakeLists.txt). The cases that read the real data run
  # without it (BRUME_DATA_DIR at an empty folder: they skip or run their
  # synthetic fallback): the same loops on larger inputs took minutes here.
  filter=$(cat build-tsan/generated/tsan_filter.txt)
  no_data=$(mktemp -d)
  BRUME_DATA_DIR=$no_data OMP_TOOL_LIBRARIES="$archer" ARCHER_OPTIONS="verbose=0" \
    TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:ignore_noninstrumented_modules=1" \
    OMP_NUM_THREADS=4 build-tsan/tests/brume_tests --gtest_filter="$filter" --gtest_brief=1
  rmdir "$no_data"
  t2=$(date +%s)
  echo "test-sanitize: TSan build $((t1 - t0)) s, tests $((t2 - t1)) s"
fi
