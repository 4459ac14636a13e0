#!/usr/bin/env bash
# The pictures of docs/gallery.md: each effect on the third-party data in
# ../shared/data (read in place, never copied). What is committed depends on
# the data's licence (docs/gallery/LICENSE): pictures derived from CC0 (Poly
# Haven) and CC BY-NC-SA (ETH3D, KITTI) data go to $OUT (docs/gallery); pictures
# derived from research-use data without redistribution terms (Middlebury,
# GeoPose3K) go to $LOCAL (docs/gallery/local, ignored by git).
# Usage: bash scripts/gallery.sh   (BRUME, DATA, OUT, LOCAL override the defaults;
# the data folder is DATA, else BRUME_DATA_DIR, else ../shared/data)
set -euo pipefail
cd "$(dirname "$0")/.."
B=${BRUME:-build/brume}
D=${DATA:-${BRUME_DATA_DIR:-../shared/data}}
OUT=${OUT:-docs/gallery}
LOCAL=${LOCAL:-docs/gallery/local}
if [ ! -d "$D" ]; then echo "gallery: no data at $D (DATA, else BRUME_DATA_DIR, else ../shared/data)" >&2; exit 2; fi
mkdir -p "$OUT" "$LOCAL"
q=(--compression jpeg:85)  # JPEG at quality 85 keeps each picture well under 200 kB
E=$D/eth3d_two_view
eth() { echo --image "$E/$1/im0.png" --disparity "$E/$1/disp0.pfm" --calib "$E/$1/calib.txt"; }

# haze with scattering blur (Hansard) on ETH3D terrace: visibility 25 m over a 6 m deep scene. The
# ground truth's holes (shadows under the tables, the glass) reach the top: without --complete on the
# preparation takes 37 % of the frame as sky (a warning says so: docs/depth.md, "When the sky is not sky")
$B haze $(eth terrace) --complete on --visibility 25 --lambda 3 --out "$OUT/eth3d-terrace-haze.jpg" "${q[@]}"
# layered fog (Zhou, Chen, Smith) lying on ETH3D playground: density 0.15/m at the camera's feet, e-folding 1.25 m.
# It warns: the unscanned buildings are taken as sky (the fog's sky colour); --complete on keeps them but
# leaves bright blobs where it fills the holes around the thin posts, so the gallery shows the warning's case
$B fog $(eth playground_1l) --density 0.15 --falloff 0.8 --camera-height 1.5 --lambda 3 \
   --out "$OUT/eth3d-playground-fog.jpg" "${q[@]}"
# depth of field (Bertalmío et al.) on ETH3D terrace, focused at 2.5 m
$B dof $(eth terrace) --complete on --focus-distance 2.5 --coc-infinity 14 --out "$OUT/eth3d-terrace-dof.jpg" "${q[@]}"
# haze on KITTI object frame 000001 (CC BY-NC-SA 3.0): its lidar scan completed (--complete auto), visibility 150 m
K=$D/kitti_object_000001
$B haze --image "$K/image_2/000001.png" --velodyne "$K/velodyne/000001.bin" --kitti-calib "$K/calib/000001.txt" \
   --visibility 150 --out "$OUT/kitti-000001-haze.jpg" "${q[@]}"
# ... its scan as projected (3.99 % of the pixels, each widened to 3x3 px) and as completed (brume depth complete)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
kl=(--velodyne "$K/velodyne/000001.bin" --kitti-calib "$K/calib/000001.txt")
$B depth convert "${kl[@]}" --like "$K/image_2/000001.png" --out "$tmp/scan.pfm" >/dev/null
$B depth complete "${kl[@]}" --image "$K/image_2/000001.png" --out "$tmp/completed.pfm" >/dev/null
${PYTHON:-/usr/bin/python3} scripts/range_picture.py "$tmp/scan.pfm" "$OUT/kitti-000001-scan.jpg" --dilate 1
${PYTHON:-/usr/bin/python3} scripts/range_picture.py "$tmp/completed.pfm" "$OUT/kitti-000001-completed.jpg"
# LiDAR fog (Hahner et al., docs/lidar.md) on the same frame at visibility 80 m: the camera frame and the scan
# from one medium; a bird's-eye view of the scan clear and foggy, and both scans projected over their images
$B haze --image "$K/image_2/000001.png" "${kl[@]}" --visibility 80 --out "$tmp/haze80.png" \
   --lidar "$K/velodyne/000001.bin" --lidar-out "$tmp/fog80.bin" >/dev/null
${PYTHON:-/usr/bin/python3} scripts/lidar_picture.py bev "$K/velodyne/000001.bin" "$tmp/fog80.bin" \
   "$OUT/kitti-000001-lidar-bev.jpg" --title "visibility 80 m" --dpi 80
${PYTHON:-/usr/bin/python3} scripts/lidar_picture.py proj "$K/velodyne/000001.bin" "$tmp/fog80.bin" \
   "$K/calib/000001.txt" "$K/image_2/000001.png" "$tmp/haze80.png" "$OUT/kitti-000001-lidar-projected.jpg"
# rain (docs/rain.md) on the same frame at 5, 25 and 100 mm/h: the drop field's streaks depth-tested against the
# completed scan, the rest of the rain as extinction; seed 1, 1/60 s, a pinhole
for r in 5 25 100; do
  $B rain --image "$K/image_2/000001.png" "${kl[@]}" --rate "$r" --rain-seed 1 \
     --out "$OUT/kitti-000001-rain$r.jpg" "${q[@]}" >/dev/null
done
# snow (docs/snow.md) on the same frame at 2 mm/h water equivalent: the flakes lit by the image's sky and
# ground, the rest as extinction, the scan through the same snowfall (a bird's-eye view clear and snowy);
# and on the demo scene
$B snow --image "$K/image_2/000001.png" "${kl[@]}" --rate 2 --snow-seed 1 --out "$OUT/kitti-000001-snow2.jpg" "${q[@]}" \
   --lidar "$K/velodyne/000001.bin" --lidar-out "$tmp/snow2.bin" >/dev/null
$B lidar snow --points "$K/velodyne/000001.bin" --rate 2 --seed 1 --out "$tmp/snow2-alone.bin" \
   --labels "$tmp/snow2.u8" >/dev/null  # (the same scan, with its labels)
${PYTHON:-/usr/bin/python3} scripts/lidar_picture.py bev "$K/velodyne/000001.bin" "$tmp/snow2.bin" \
   "$OUT/kitti-000001-snow-bev.jpg" --title "snow 2 mm/h" --echoes "flake returns" --labels "$tmp/snow2.u8" --dpi 80
$B demo --out-dir "$tmp/demo-snow" --width 640 --height 448 >/dev/null
$B snow --image "$tmp/demo-snow/clean.png" --range "$tmp/demo-snow/range.exr" --fov-y 55 --rate 2 --snow-seed 1 \
   --out "$OUT/demo-snow.jpg" "${q[@]}" >/dev/null
# wet ground (docs/wet-ground.md) on the same frame: a 1 mm film on the road (KITTI's camera 1.65 m up), its
# mirror image marched through the completed range; and on the demo scene (brume demo; 1.6 m up, 5 deg down)
$B wet --image "$K/image_2/000001.png" "${kl[@]}" --camera-height 1.65 --film 1 \
   --out "$OUT/kitti-000001-wet.jpg" "${q[@]}" >/dev/null
$B demo --out-dir "$tmp/demo" --width 640 --height 448 >/dev/null
$B wet --image "$tmp/demo/clean.png" --range "$tmp/demo/range.exr" --fov-y 55 --camera-height 1.6 --pitch -5 \
   --film 1.5 --out "$OUT/demo-wet.jpg" "${q[@]}" >/dev/null
# the turbidity fit (Preetham sky) on each Poly Haven sky
for s in park sky sunrise; do
  $B sky fit --image "$D/sky_hdr_polyhaven/$s.hdr" --sun auto --out "$LOCAL/fit-$s.json" --plot "$OUT/polyhaven-$s-fit.png"
done

# Research-use data: written to $LOCAL only.
M=$D/middlebury2005_thirdsize/Art
mb=(--image "$M/view1.png" --disparity "$M/disp1.png" --fx 1246.667 --baseline 0.16
    --disparity-scale 0.3333333 --disparity-offset 66.667)
$B haze "${mb[@]}" --visibility 8 --lambda 4 --out "$LOCAL/middlebury-art-haze.jpg" "${q[@]}"
$B dof "${mb[@]}" --focus-distance 1.3 --coc-infinity 12 --out "$LOCAL/middlebury-art-dof.jpg" "${q[@]}"
G=$D/geopose3k_matterhorn
geo=(--image "$G/photo.jpg" --range "$G/distance.pfm" --unknown-value -1)
$B aerial "${geo[@]}" --turbidity 4 --out "$LOCAL/matterhorn-t4.jpg" "${q[@]}"
for t in 1.6 2 4 8; do
  $B aerial "${geo[@]}" --turbidity "$t" --remove --out "$LOCAL/matterhorn-remove-t$t.exr"
  $B aerial "${geo[@]}" --turbidity "$t" --altitude 2500 --remove --out "$LOCAL/matterhorn-remove-t$t-2500m.exr"
done
echo "gallery: $(find "$OUT" -maxdepth 1 -type f | wc -l) files in $OUT, $(find "$LOCAL" -maxdepth 1 -type f | wc -l) in $LOCAL"
