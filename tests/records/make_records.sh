#!/bin/bash
# Writes the stored records of one schema (tests/records/README.md): each
# command below run by BRUME with --record, its outputs beside the record in
# schema-N/. Paths are relative to tests/records, where the test replays them.
#
#   tests/records/make_records.sh BRUME inputs            # the inputs (once; committed)
#   tests/records/make_records.sh BRUME N [NAME ...]      # N: the schema BRUME writes;
#                                                         # NAMEs: only those records
#
# Run it only with a build that writes schema N, to store records of that
# schema: a stored record is what its build wrote, never rewritten later.
set -euo pipefail
brume=$(realpath "$1")
what=$2
only=("${@:3}")
cd "$(dirname "$0")"
# Run as "brume" (exec -a): a record's argv[0] is then the command's name,
# not the path of the build on the machine that wrote it.
b() { echo "+ brume $*" >&2; (exec -a brume "$brume" "$@"); }

if [ "$what" = inputs ]; then
  mkdir -p inputs
  tmp=$(mktemp -d)
  b demo --out-dir "$tmp" --width 48 --height 32 >/dev/null
  cp "$tmp/clean.png" "$tmp/range.exr" inputs/
  b depth convert --range inputs/range.exr --out "$tmp/range.pfm" >/dev/null
  b sky render --turbidity 4 --sun-zenith 40 --sun-azimuth 100 --width 48 --height 24 --out inputs/sky.pfm
  /usr/bin/python3 make_inputs.py inputs "$tmp/range.pfm"   # numpy
  rm -rf "$tmp"
  exit 0
fi

schema=$what
o=schema-$schema
mkdir -p "$o"
frame="--image inputs/clean.png --range inputs/range.exr"
wanted() { [ ${#only[@]} -eq 0 ] || printf '%s\n' "${only[@]}" | grep -qx "$1"; }
# rec NAME ARGS...: the command with --record schema-N/NAME.json
rec() { local name=$1; shift; if wanted "$name"; then b "$@" --record "$o/$name.json"; fi; }
# own NAME ARGS...: a command whose --out schema-N/NAME.json holds its record (sky fit)
own() { local name=$1; shift; if wanted "$name"; then b "$@"; fi; }

# haze in metres (the sky rule schema 3 changed: sky-rule), in normalised units, with DOF after it
rec haze-visibility haze $frame --visibility 200 --albedo 0.9 --lambda 3 \
    --out "$o/haze-visibility.pfm" --transmission "$o/haze-visibility-t.pfm"
rec haze-kappa haze $frame --kappa-s 1.5 --kappa-a 0.1 --lambda 4 --airlight 0.7,0.72,0.75 \
    --scheme invariant --edge-rate min --out "$o/haze-kappa.pfm" --scale-map "$o/haze-kappa-sigma.pfm"
rec haze-dof haze $frame --visibility 800 --lambda 2 --dof-focus-distance 3.9 --dof-coc-infinity 6 --fov-y 55 \
    --out "$o/haze-dof.pfm"
# fog: a layered medium and a constant one, both in metres (sky-rule)
rec fog-layered fog $frame --density 0.01 --falloff 0.02 --camera-height 1.6 --fov-y 55 --lambda 2 \
    --out "$o/fog-layered.pfm"
rec fog-constant fog $frame --profile constant --density 0.02 --albedo 0.95 --lambda 3 --airlight 0.62,0.64,0.66 \
    --out "$o/fog-constant.pfm"
rec aerial aerial $frame --turbidity 4 --altitude 300 --lambda 2 --out "$o/aerial.pfm"
rec insert insert $frame --object inputs/object.pfm --object-range inputs/object-range.pfm --turbidity 6 \
    --out "$o/insert.pfm"
rec dof dof $frame --focus-distance 3.9 --coc-infinity 8 --fov-y 55 --out "$o/dof.pfm"
rec dof-lens dof $frame --focus-distance 0.3 --f-number 1.4 --focal-length 24 --sensor-width 36 \
    --out "$o/dof-lens.pfm"
rec blur-sigma blur --image inputs/clean.png --sigma 3 --out "$o/blur-sigma.pfm"
rec blur-map blur --image inputs/clean.png --scale-map inputs/scale.pfm --precision f16 --out "$o/blur-map.pfm"
rec depth-convert depth convert --range inputs/range.exr --kind z --fov-y 55 --out "$o/depth-convert.pfm"
rec depth-convert-velodyne depth convert --velodyne inputs/scan.bin --kitti-calib inputs/kitti-calib.txt \
    --width 48 --height 32 --out "$o/depth-convert-velodyne.pfm"
rec depth-prepare depth prepare --range inputs/range.exr --sky-margin 3 --out "$o/depth-prepare.pfm"
rec sky-render sky render --turbidity 3 --sun-zenith 50 --sun-azimuth 10 --width 48 --height 24 --ground 0.1,0.1,0.1 \
    --out "$o/sky-render.pfm"
own sky-fit sky fit --image inputs/sky.pfm --sun-zenith 40 --sun-azimuth 100 --out "$o/sky-fit.json"

[ "$schema" -ge 3 ] || exit 0
# What schema 3's brume added: depth completion (on its own and in an effect), stereo matching,
# LiDAR fog (on its own and as a camera effect's companion scan); and a range whose renderer
# background (1e10 m, where the demo's sky is unknown) is read as a range.
rec depth-complete depth complete --image inputs/clean.png --velodyne inputs/scan.bin \
    --kitti-calib inputs/kitti-calib.txt --out "$o/depth-complete.pfm" --confidence "$o/depth-complete-c.pfm"
rec haze-complete haze --image inputs/clean.png --velodyne inputs/scan.bin --kitti-calib inputs/kitti-calib.txt \
    --complete auto --visibility 300 --lambda 2 --out "$o/haze-complete.pfm"
rec depth-stereo depth stereo --left inputs/left.pfm --right inputs/right.pfm --fx 30.7 --baseline 0.1 \
    --out "$o/depth-stereo.pfm" --confidence "$o/depth-stereo-c.pfm"
rec lidar-fog lidar fog --points inputs/scan.bin --visibility 40 --seed 2 --out "$o/lidar-fog.bin"
rec haze-lidar haze $frame --visibility 80 --lidar inputs/scan.bin --lidar-out "$o/haze-lidar-scan.bin" \
    --lidar-seed 3 --out "$o/haze-lidar.pfm"
rec haze-background haze --image inputs/clean.png --range inputs/range-background.pfm --visibility 500 \
    --out "$o/haze-background.pfm"
