# CMake toolchain file: cross-build for 64-bit ARM Linux with Debian's
# g++-aarch64-linux-gnu, the arm64 libraries from Debian's multiarch packages
# (libhwy-dev:arm64, libgtest-dev:arm64, libgomp1:arm64:
# /usr/lib/aarch64-linux-gnu), run through qemu-user
# (scripts/install-deps.sh --aarch64 installs all of them).
#   cmake -S tests/engine -B build-aarch64 -DCMAKE_TOOLCHAIN_FILE=cmake/aarch64-linux-gnu.cmake
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
# Debian's multiarch layout: the cross compiler searches /usr/include and
# /usr/lib/aarch64-linux-gnu itself; find_* looks under the library
# architecture's folders (CMAKE_LIBRARY_ARCHITECTURE) and never takes the
# host's x86-64 libraries.
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)
set(CMAKE_FIND_ROOT_PATH /usr/aarch64-linux-gnu)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY BOTH)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE BOTH)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE BOTH)
# ctest (and try_run) run the aarch64 binaries through qemu-aarch64; its
# default CPU, `max`, has SVE and SVE2. Without -L: the program's loader and
# libraries are the multiarch arm64 ones (/lib/ld-linux-aarch64.so.1,
# /lib/aarch64-linux-gnu: libc6:arm64, which libhwy1:arm64 brings, and
# libgomp1:arm64). With -L /usr/aarch64-linux-gnu the loader would be the
# cross package's (libc6-arm64-cross 2.36-8cross1) and, through qemu's
# fall-back to the host's paths, libc.so.6 the multiarch one (2.36-9+deb12u14):
# a program that starts a thread then hangs in pthread_create (seen with
# two threads printing a line, 2026-12-06).
set(CMAKE_CROSSCOMPILING_EMULATOR qemu-aarch64)
