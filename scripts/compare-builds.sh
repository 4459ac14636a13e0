#!/usr/bin/env bash
# Runs one of every command on the demo scene with two brume binaries and
# compares what they write: every image's pixels (float PFM outputs, byte for
# byte) and every record's content less its time, argv and timings.
#   scripts/compare-builds.sh OLD_BRUME NEW_BRUME [WORK_DIR]
# Exit 1 at the first difference. Used to hold refactors to bit-identical
# outputs on the CPU backend (issue #37).
# COMPARE_RECORDS=superset: a change that adds to the records (a new schema's
# keys) passes when every value the old record holds is the new one's at the
# same place, but for schema_version and the places COMPARE_MOVED lists
# ("OLD=NEW" dotted paths, space-separated: a parameter that moved block);
# the keys only the new record has are printed once per run.
set -euo pipefail
old=$1 new=$2
work=${3:-$(mktemp -d)}
mkdir -p "$work"
cd "$work"
"$old" demo --out-dir scene --width 320 --height 224 >/dev/null 2>&1
"$old" sky render --turbidity 3 --sun-zenith 50 --sun-azimuth 10 --width 256 --height 128 --out scene/sky.exr >/dev/null 2>&1
S=scene
runs=(
  "haze --image $S/clean.png --range $S/range.exr --visibility 800 --out OUT.pfm --transmission OUT.t.pfm --scale-map OUT.s.pfm --record OUT.json"
  "haze --image $S/clean.png --range $S/range.exr --kappa-s 0.4 --lambda 10 --out OUT.pfm --record OUT.json"
  "haze --image $S/clean.png --range $S/range.exr --visibility 800 --dof-focus-distance 30 --dof-f-number 2 --dof-focal-length 35 --dof-sensor-width 36 --out OUT.pfm --record OUT.json"
  "fog --image $S/clean.png --range $S/range.exr --density 0.01 --falloff 0.02 --lambda 4 --camera-height 2 --fov-x 60 --out OUT.pfm --record OUT.json"
  "aerial --image $S/clean.png --range $S/range.exr --turbidity 4 --lambda 2 --out OUT.pfm --record OUT.json"
  "dof --image $S/clean.png --range $S/range.exr --focus-distance 50 --coc-infinity 6 --fov-x 60 --out OUT.pfm --record OUT.json"
  "blur --image $S/clean.png --sigma 3 --out OUT.pfm --record OUT.json"
  "depth convert --range $S/range.exr --out OUT.pfm --record OUT.json"
  "depth prepare --range $S/range.exr --out OUT.pfm --record OUT.json"
  "sky render --turbidity 3 --sun-zenith 40 --sun-azimuth 10 --width 64 --height 48 --out OUT.pfm --record OUT.json"
  "aerial coefficients --out OUT.csv"
  "compare --a $S/clean.png --b $S/haze.png --json OUT.json"
  "sky fit --image $S/sky.exr --sun-zenith 50 --sun-azimuth 10 --out OUT.json"
  "sample --effect fog --seed 4 --key frame/1"
  "haze --image $S/clean.png --range $S/range.exr --visibility 800 --backend gpu --out OUT.pfm"
  "fog --image $S/clean.png --range $S/range.exr --density 0.01 --falloff 0.02 --lambda 4 --camera-height 2 --fov-x 60 --backend gpu --out OUT.pfm"
  "aerial --image $S/clean.png --range $S/range.exr --turbidity 4 --lambda 2 --backend gpu --out OUT.pfm"
  "dof --image $S/clean.png --range $S/range.exr --focus-distance 50 --coc-infinity 6 --fov-x 60 --backend gpu --out OUT.pfm"
  "sky render --turbidity 3 --sun-zenith 40 --sun-azimuth 10 --width 64 --height 48 --backend gpu --out OUT.pfm"
  "blur --image $S/clean.png --sigma 3 --backend gpu --out OUT.pfm"
)
i=0
for r in "${runs[@]}"; do
  i=$((i + 1))
  for side in old new; do
    bin=${!side}
    args=${r//OUT/$side-$i}
    # shellcheck disable=SC2086
    "$bin" $args >"$side-$i.stdout" 2>"$side-$i.stderr" || { echo "compare-builds: $side failed: brume $args"; cat "$side-$i.stderr"; exit 1; }
  done
  for f in old-$i.*; do
    g=new-${f#old-}
    case $f in
      *.json) python3 - "$f" "$g" "old-$i" "new-$i" <<'PY' || { echo "compare-builds: records differ: brume $r"; exit 1; }
import json, sys
def clean(j):
    if isinstance(j, dict):
        return {k: clean(v) for k, v in j.items() if k not in ("time_utc", "argv", "timing", "path") and not k.endswith("_ms")}
    if isinstance(j, list):
        return [clean(v) for v in j]
    return j
a, b = (clean(json.loads(open(p).read().replace(n, "X"))) for p, n in ((sys.argv[1], sys.argv[3]), (sys.argv[2], sys.argv[4])))
import os
if os.environ.get("COMPARE_RECORDS") == "superset":
    moved = dict(m.split("=", 1) for m in os.environ.get("COMPARE_MOVED", "").split())
    def leaves(j, at=""):
        if isinstance(j, dict):
            for k, v in j.items():
                yield from leaves(v, at + "." + k if at else k)
        else:
            yield at, j
    def get(j, path):
        for k in path.split("."):
            if not isinstance(j, dict) or k not in j: return KeyError
            j = j[k]
        return j
    bad = [(p, v, get(b, moved.get(p, p))) for p, v in leaves(a) if p.split(".")[-1] != "schema_version" and get(b, moved.get(p, p)) != v]
    for p, v, w in bad: print("  differs:", p, json.dumps(v)[:200], "|", "(absent)" if w is KeyError else json.dumps(w)[:200])
    added = sorted(p for p, _ in leaves(b) if get(a, p) is KeyError and p not in moved.values())
    if added: print("  new keys:", " ".join(added)[:1500])
    sys.exit(1 if bad else 0)
if a != b:
    for k in sorted(set(a) | set(b)):
        if a.get(k) != b.get(k): print("  differs:", k, json.dumps(a.get(k))[:300], "|", json.dumps(b.get(k))[:300])
    sys.exit(1)
PY
      ;;
      *.stderr|*.stdout) sed "s/old-$i/X/g" "$f" | grep -v "ms" >"$f.cmp" || true
                         sed "s/new-$i/X/g" "$g" | grep -v "ms" >"$g.cmp" || true
                         cmp -s "$f.cmp" "$g.cmp" || { echo "compare-builds: messages differ: brume $r"; diff "$f.cmp" "$g.cmp"; exit 1; } ;;
      *.cmp) ;;
      *) cmp -s "$f" "$g" || { echo "compare-builds: $f and $g differ: brume $r"; exit 1; } ;;
    esac
  done
  echo "same: brume $r"
done
echo "compare-builds: all ${#runs[@]} runs identical"
