#!/usr/bin/env python3
"""Renders with Debian's Blender, then brume on them, as an artist would (ctest
blender_live; issue #50).

Skips (exit 77, ctest's SKIP_RETURN_CODE) with a message when `blender` is not
installed: it is not a dependency of the set-up commands (apt-get install
blender adds it). Otherwise, in a scratch folder:

1. examples/blender_fixtures.py renders 64 x 48 multilayer OpenEXR files with
   Cycles and Eevee (Combined, AO, Depth, Mist, Normal), and a 32 x 48
   portrait with --sensor-fit VERTICAL, each with the projection Blender
   computed for it (NAME.json).
2. `brume haze` on each with the camera as Blender states it (--focal-length,
   --sensor-width/--sensor-height, --sensor-fit, --lens-shift from the .json):
   no layer named is refused with the list; with --image-layer
   ViewLayer.Combined and --z on the same file the Depth pass is found, the
   transmission on the scene equals exp(-3.912 r/V) (r from the Z pass and
   Blender's own projection, in double precision here) within 2e-3, the sky
   beyond the horizon margin transmits <= 4e-4, and the record names the
   layer and the channel.
3. `brume haze --keep-layers` writes a file whose every layer Blender's
   compositor shows as a socket of its Image node (Combined, AO, Depth, Mist,
   Normal, Medium, Transmission, BlurScale).
Eevee needs an OpenGL context; Blender 3.4 renders it headless here (-b) on
Mesa's llvmpipe in about a minute. Set BRUME_BLENDER_EEVEE=0 to skip it.
"""
import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile

import numpy as np

SKIP = 77


def pfm(path):
    with open(path, "rb") as f:
        kind = f.readline().strip()
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        c = 3 if kind == b"PF" else 1
        a = np.fromfile(f, "<f4" if scale < 0 else ">f4").reshape(h, w, c)[::-1]
    return a[:, :, 0] if c == 1 else a


def channel(exr, name):
    """One channel of an OpenEXR file as OpenImageIO's oiiotool reads it (the peer)."""
    out = subprocess.run(["oiiotool", "--dumpdata", exr], check=True, capture_output=True, text=True).stdout
    names = None
    rows = {}
    for line in out.splitlines():
        m = re.match(r"\s*Pixel \((\d+), (\d+)\): (.*)", line)
        if m:
            rows[(int(m[1]), int(m[2]))] = [float(v) for v in m[3].split()]
    info = subprocess.run(["oiiotool", "--info", "-v", exr], check=True, capture_output=True, text=True).stdout
    names = re.search(r"channel list: (.*)", info)[1]
    names = [n.split(" (")[0].strip() for n in names.split(", ")]
    k = names.index(name)
    w = max(x for x, _ in rows) + 1
    h = max(y for _, y in rows) + 1
    a = np.zeros((h, w))
    for (x, y), v in rows.items():
        a[y, x] = v[k]
    return a


def lens_flags(side):
    cam = side["camera"]
    f = ["--focal-length", repr(cam["lens_mm"]), "--sensor-fit", cam["sensor_fit"].lower(),
         "--lens-shift", f"{cam['shift_x']!r},{cam['shift_y']!r}"]
    f += ["--sensor-height", repr(cam["sensor_height_mm"])] if cam["sensor_fit"] == "VERTICAL" else \
         ["--sensor-width", repr(cam["sensor_width_mm"])]
    return f


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repo", required=True)
    ap.add_argument("--brume", required=True)
    a = ap.parse_args()
    blender = shutil.which("blender")
    if not blender:
        print("blender_live: skipped: blender is not installed (apt-get install -y blender; it is not a dependency "
              "of scripts/install-deps.sh); the committed renders in tests/renders are tested without it")
        return SKIP
    script = os.path.join(a.repo, "examples", "blender_fixtures.py")
    work = tempfile.mkdtemp(prefix="brume_blender_")
    failures = []

    def check(ok, what):
        print(("ok   " if ok else "FAIL ") + what)
        if not ok:
            failures.append(what)

    renders = [("cycles", ["--engine", "cycles"]), ("portrait", ["--engine", "cycles", "--width", "32", "--sensor-fit", "VERTICAL"])]
    if os.environ.get("BRUME_BLENDER_EEVEE", "1") != "0":
        renders.append(("eevee", ["--engine", "eevee"]))
    for name, args in renders:
        exr = os.path.join(work, name + ".exr")
        r = subprocess.run([blender, "-b", "--factory-startup", "--python", script, "--", *args, "--out", exr],
                           capture_output=True, text=True)
        if r.returncode != 0 or not os.path.exists(exr):
            check(False, f"{name}: blender rendered {exr}:\n{r.stdout[-2000:]}\n{r.stderr[-2000:]}")
            continue
        side = json.load(open(os.path.join(work, name + ".json")))
        W, H = side["width"], side["height"]
        P = side["projection"]
        fx, fy = P[0][0] * W / 2, P[1][1] * H / 2
        cx, cy = (1 - P[0][2]) * W / 2 - 0.5, (1 + P[1][2]) * H / 2 - 0.5
        base = [a.brume, "haze", "--image", exr, "--z", exr, *lens_flags(side), "--visibility", "100", "--lambda", "0"]
        r = subprocess.run(base + ["--out", os.path.join(work, name + "-x.exr")], capture_output=True, text=True)
        check(r.returncode == 2 and "ViewLayer.AO, ViewLayer.Combined" in r.stderr
              and not os.path.exists(os.path.join(work, name + "-x.exr")),
              f"{name}: no layer named: exit 2 with the list ({r.returncode}: {r.stderr.strip()[:200]})")
        out, t, rec = (os.path.join(work, name + s) for s in ("-haze.exr", "-t.pfm", ".record.json"))
        r = subprocess.run(base + ["--image-layer", "ViewLayer.Combined", "--out", out, "--transmission", t,
                                   "--record", rec], capture_output=True, text=True)
        check(r.returncode == 0, f"{name}: brume haze --image-layer ViewLayer.Combined ({r.stderr.strip()[:300]})")
        if r.returncode != 0:
            continue
        j = json.load(open(rec))
        check(j["inputs"]["image"]["layer"] == "ViewLayer.Combined" and
              j["inputs"]["depth"]["channel"] == "ViewLayer.Depth.Z", f"{name}: the record names the layer and channel")
        z = channel(exr, "ViewLayer.Depth.Z")
        tau = pfm(t)
        v, u = np.mgrid[0:H, 0:W]
        rng = z * np.sqrt(1 + ((u - cx) / fx) ** 2 + ((v - cy) / fy) ** 2)
        scene = (z < 1e9) & (z != 65504)  # the renderers' backgrounds: Cycles 1e10, Eevee 65504
        ref = np.exp(-3.912 * rng / 100.0)
        worst = float(np.max(np.abs(tau[scene] - ref[scene])))
        check(worst <= 2e-3, f"{name}: |tau - exp(-3.912 r/V)| <= 2e-3 on {int(scene.sum())} scene pixels (largest {worst:.3g})")
        far = ~scene
        for dy in range(-9, 10):
            for dx in range(-9, 10):
                if dx * dx + dy * dy <= 81:
                    far &= ~np.roll(np.roll(np.pad(scene, 10), dy, 0), dx, 1)[10:-10, 10:-10]
        sky = float(tau[far].max()) if far.any() else 0.0
        check(far.sum() > 50 and sky <= 4e-4, f"{name}: sky beyond the margin transmits <= 4e-4 ({int(far.sum())} px, largest {sky:.3g})")
        print(f"{name}: {W}x{H}, fx {fx:.4f} cx {cx:.4f} cy {cy:.4f}; largest |tau - exp(-3.912 r/V)| {worst:.3g}; "
              f"sky tau <= {sky:.3g}")
        if name != "cycles":
            continue
        comp = os.path.join(work, "comp.exr")
        r = subprocess.run(base[:-2] + ["--lambda", "2", "--image-layer", "ViewLayer.Combined", "--keep-layers",
                                        "--out", comp], capture_output=True, text=True)
        check(r.returncode == 0, f"--keep-layers ({r.stderr.strip()[:300]})")
        probe = os.path.join(work, "probe.py")
        with open(probe, "w") as f:
            f.write("import bpy, sys\n"
                    "img = bpy.data.images.load(sys.argv[sys.argv.index('--') + 1])\n"
                    "bpy.context.scene.use_nodes = True\n"
                    "n = bpy.context.scene.node_tree.nodes.new('CompositorNodeImage')\n"
                    "n.image = img\n"
                    "print('SOCKETS', ','.join(o.name for o in n.outputs))\n")
        r = subprocess.run([blender, "-b", "--factory-startup", "--python", probe, "--", comp], capture_output=True, text=True)
        m = re.search(r"SOCKETS (.*)", r.stdout)
        sockets = m[1].split(",") if m else []
        want = ["Combined", "Alpha", "AO", "Depth", "Mist", "Normal", "Medium", "Transmission", "BlurScale"]
        check(all(s in sockets for s in want), f"Blender's compositor shows {want} (it shows {sockets})")
    print(f"blender_live: {len(failures)} failed; files in {work}")
    if not failures:
        shutil.rmtree(work)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
