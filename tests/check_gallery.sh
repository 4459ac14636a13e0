#!/usr/bin/env bash
# ctest gallery_pictures_are_small: scripts/gallery.sh runs on the shared data
# into a scratch folder, and every picture it would commit is at most 200 kB,
# 3 MB in all (issue #39); skipped (exit 77) without the data. The data
# folder is the environment variable BRUME_DATA_DIR when set, else $3 (the
# build's ../shared/data).
set -euo pipefail
repo=$1 brume=$2 data=${BRUME_DATA_DIR:-$3}
if [ ! -d "$data" ] || [ -z "$(ls -A "$data")" ]; then
  echo "skip: the data folder $data is absent or empty (BRUME_DATA_DIR, else ../shared/data beside the repository)"
  exit 77
fi
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
BRUME=$brume DATA=$data OUT=$out/committed LOCAL=$out/local bash "$repo/scripts/gallery.sh"
total=0 bad=0
for f in "$out"/committed/*; do
  [ -f "$f" ] || continue
  s=$(stat -c %s "$f"); total=$((total + s))
  if [ "$s" -gt 204800 ]; then echo "too large: $(basename "$f") $s bytes (at most 200 kB)"; bad=1; fi
done
n=$(ls "$out"/committed | wc -l)
echo "gallery: $n pictures, $total bytes in all"
[ "$n" -ge 6 ] || { echo "expected at least 6 pictures"; bad=1; }
[ "$total" -le 3145728 ] || { echo "more than 3 MB in all"; bad=1; }
for f in "$repo"/docs/gallery/*.jpg "$repo"/docs/gallery/*.png; do
  [ -f "$out/committed/$(basename "$f")" ] || { echo "committed $(basename "$f") is not made by scripts/gallery.sh"; bad=1; }
done
exit $bad
