#!/usr/bin/env bash
# The single source of brume's dependencies: every Debian 12 package the build,
# the demo, the tests and the benchmarks need. Idempotent; needs root (or sudo).
#   install-deps.sh            the packages below (x86-64 or any host)
#   install-deps.sh --aarch64  only those of the aarch64 check of the diffusion
#                              engine (scripts/test-aarch64.sh), not for everyone:
#                              it adds arm64 to dpkg's architectures (every later
#                              apt-get update then reads arm64's lists too) for
#                              arm64 builds of Highway, GoogleTest and libgomp,
#                              and brings a cross compiler and qemu (72 MB to
#                              download, 352 MB installed); the README's build needs none of it.
set -euo pipefail
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
update=0
if [ "${1:-}" = "--aarch64" ]; then
  PKGS=(
    g++-aarch64-linux-gnu qemu-user      # the cross compiler; qemu-aarch64 runs the tests
    libhwy-dev:arm64 libgtest-dev:arm64  # Highway and GoogleTest built for arm64 (multiarch)
    libgomp1:arm64                       # OpenMP's runtime beside the multiarch libc (cmake/aarch64-linux-gnu.cmake)
  )
  if ! dpkg --print-foreign-architectures | grep -qx arm64; then
    $SUDO dpkg --add-architecture arm64
    update=1
  fi
elif [ $# -gt 0 ]; then
  echo "install-deps: unknown option '$1' (none, or --aarch64)" >&2
  exit 2
else
PKGS=(
  build-essential cmake pkg-config git
  libopenimageio-dev openimageio-tools   # image I/O: PNG, JPEG, TIFF, OpenEXR, PFM, HDR
  libopencv-imgproc-dev                  # connected components, exact EDT (range preparation); benchmark peer
  libopencv-calib3d-dev                  # StereoSGBM and ORB (brume depth stereo, --stereo-right)
  libeigen3-dev                          # bounded least squares (sky turbidity fit: Levenberg-Marquardt)
  libcli11-dev nlohmann-json3-dev        # command line, parameter records
  libssl-dev                             # SHA-256 of input files in the records
  libspng-dev                            # PNG read and written without loading OpenImageIO (src/io/formats/png.cpp)
  libpng-dev                             # the tests write unusual PNGs (interlaced, palette) with libpng
  libjpeg-dev                            # 8-bit grey and colour JPEG read without loading OpenImageIO
  libtiff-dev                            # the common TIFF files read without loading OpenImageIO
  libopenexr-dev                         # the common OpenEXR files read without loading OpenImageIO
  libgtest-dev libbenchmark-dev          # tests, benchmarks
  libegl-dev libgles-dev                 # GPU backend: headless EGL + OpenGL ES 3.2 headers and loaders
  libegl-mesa0 libgl1-mesa-dri           # Mesa's EGL and llvmpipe, the GPU the tests run on without one
  python3-dev pybind11-dev                # the Python module: CPython headers, the C++ binding layer
  python3-numpy                          # the Python module's arrays (numpy in, numpy out)
  python3-pytest                         # the Python tests (ctest `python`)
  python3-matplotlib                     # the diffusion study's plots (brume.plots)
  python3-distributed                    # brume.dask: a batch's frames as Dask tasks (and its LocalCluster test)
  python3-torch python3-torchvision      # brume.transforms' torch tensors and DataLoader tests, examples/train_loader.py
  clang-14 libclang-rt-14-dev            # sanitizer builds and libFuzzer (scripts/test-sanitize.sh, fuzz/)
  libomp-14-dev                          # LLVM OpenMP + Archer, so that ThreadSanitizer sees OpenMP's synchronisation
  libhwy-dev                             # SIMD kernels written once, dispatched per CPU (Highway, src/core/simd.hpp)
  libcpp-httplib-dev                     # brume view's request parsing and routes, behind its own front (0.7 MB)
  chromium chromium-driver python3-selenium python3-pil  # brume view's page tested in headless Chromium (SwiftShader WebGL2; ~380 MB)
)
fi
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ] && [ $update -eq 0 ]; then
  echo "install-deps: all ${#PKGS[@]} packages present"
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
