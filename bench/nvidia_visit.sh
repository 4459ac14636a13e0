#!/usr/bin/env bash
# One prepared visit to an NVIDIA machine: the GPU figures the README still
# lacks (haze backend, aerial, fog, sky passes, rain's and snow's splat, the study's GPU column) and the
# GPU tests on real hardware. Run from the repository root with an existing
# Release build in build/; results go to ${OUT:-nvidia-out}/ (at most 8 files).
#
# The binaries link ~260 Debian 12 libraries (OpenImageIO alone brings ffmpeg,
# OpenVDB and GDAL: 344 MB, ~100 MB compressed). On a machine without them,
# carry them beside the binaries (ldd build/brume) and point LD_LIBRARY_PATH
# there, with glvnd's libEGL/libGLESv2/libGLdispatch and
# __EGL_VENDOR_LIBRARY_FILENAMES naming the NVIDIA EGL vendor file.
set -u
OUT=${OUT:-nvidia-out}
mkdir -p "$OUT"
{ date -u; nvidia-smi -L 2>&1; lscpu | grep -E 'Model name|^CPU\(s\)'; } > "$OUT/machine.txt"
timeout 150 build/bench/brume_bench_gpu --runs 3 --size 1600x1120 --size 3840x2160 > "$OUT/bench_gpu.md" 2>&1
d=$(mktemp -d)
{ build/brume demo --out-dir "$d" --width 1600 --height 1120
  for i in 1 2 3; do
    build/brume aerial --image "$d/clean.png" --range "$d/range.exr" --turbidity 8 --lambda 15 --out "$d/a_gpu.exr" --backend gpu --timing
    build/brume aerial --image "$d/clean.png" --range "$d/range.exr" --turbidity 8 --lambda 15 --out "$d/a_cpu.exr" --backend cpu --timing
    build/brume haze --image "$d/clean.png" --range "$d/range.exr" --visibility 1000 --lambda 24 --out "$d/h_gpu.exr" --backend gpu --timing
    build/brume fog --image "$d/clean.png" --range "$d/range.exr" --fov-y 55 --camera-height 1.6 --pitch -5 \
      --profile exponential --density 0.02 --falloff 0.05 --out "$d/f_gpu.exr" --backend gpu --timing
    build/brume sky render --turbidity 4 --sun-zenith 40 --sun-azimuth 135 --projection equirectangular \
      --width 4096 --height 2048 --out "$d/sky.exr" --backend gpu --timing
  done
  build/brume compare --a "$d/a_gpu.exr" --b "$d/a_cpu.exr"
} > "$OUT/effects.txt" 2>&1
# Rain's and snow's streak splat on the GPU against the CPU's (bench_rain.cpp's splat mode: the
# same streaks, each stage timed, the images' max difference), and the two commands end to end.
{ timeout 150 build/bench/brume_bench_rain 3 splat 5 25 100
  K=../shared/data/kitti_object_000001
  if [ -d "$K" ]; then
    for be in gpu cpu; do
      build/brume rain --image $K/image_2/000001.png --velodyne $K/velodyne/000001.bin --kitti-calib $K/calib/000001.txt \
        --rate 25 --rain-seed 1 --out "$d/rain_$be.exr" --record "$d/rain_$be.json" --backend $be --timing
      build/brume snow --image $K/image_2/000001.png --velodyne $K/velodyne/000001.bin --kitti-calib $K/calib/000001.txt \
        --rate 2 --out "$d/snow_$be.exr" --backend $be --timing
    done
    grep -A9 '"gpu_splat_timing"' "$d/rain_gpu.json"
    build/brume compare --a "$d/rain_gpu.exr" --b "$d/rain_cpu.exr"
    build/brume compare --a "$d/snow_gpu.exr" --b "$d/snow_cpu.exr"
  fi
} > "$OUT/rain_splat.txt" 2>&1
{ BRUME_REQUIRE_GPU=1 timeout 120 build/tests/brume_tests --gtest_filter='*Gpu*:*GPU*' --gtest_brief=1; echo "gpu tests rc=$?"; } > "$OUT/tests.log" 2>&1
timeout 60 build/brume study diffusion --quick --backend gpu --out-dir "$d/sq" > "$OUT/study_quick.md" 2>&1
cat "$d/sq/summary.md" >> "$OUT/study_quick.md" 2>/dev/null
timeout 240 build/brume study diffusion --backend gpu --out-dir "$d/sf" > "$d/sf.log" 2>&1
tar -C "$d" -cf "$OUT/study_full.tar" sf.log sf 2>/dev/null
ls -la "$OUT"
