#!/usr/bin/python3
"""The synthetic inputs of the stored records (tests/records/README.md), beside
those brume's own commands write (make_records.sh): a KITTI-format scan and
its calibration, a virtual object for insert, a scale map for blur and a
stereo pair. Deterministic (numpy's PCG64 with fixed seeds); written once and
committed, like every input here: run it only to make a new input.

Usage: make_inputs.py DIR RANGE_PFM   (the demo's range as PFM, for range-background.pfm)
"""
import sys
from pathlib import Path

import numpy as np

W, H = 48, 32                       # the demo scene's size in the records
FY = (H / 2) / np.tan(np.radians(27.5))  # the demo's 55 degree vertical field of view


def write_pfm(path, a):
    """PFM, little-endian, rows bottom to top (brume's and Middlebury's reading)."""
    a = np.asarray(a, dtype="<f4")
    kind = b"PF" if a.ndim == 3 else b"Pf"
    with open(path, "wb") as f:
        f.write(kind + b"\n%d %d\n-1.0\n" % (a.shape[1], a.shape[0]))
        f.write(np.ascontiguousarray(a[::-1]).tobytes())


def read_pfm(path):
    with open(path, "rb") as f:
        kind = f.readline().strip()
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        c = 3 if kind == b"PF" else 1
        a = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4").reshape(h, w, c)[::-1]
    return a[..., 0] if c == 1 else a


def main(out, range_pfm):
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.Generator(np.random.PCG64(49))

    # A scan in Velodyne axes (x forward, y left, z up; KITTI .bin: float32
    # x, y, z, reflectance): 800 returns at 3 to 60 m, most in the camera's
    # view, a few behind it, the ground 1.6 m below the sensor.
    n = 800
    az = rng.uniform(-0.6, 0.6, n)
    az[:50] += np.pi                              # behind the camera: projected nowhere
    el = rng.uniform(-0.40, 0.05, n)
    r = rng.uniform(3.0, 60.0, n)
    ground = r * np.sin(-el) > 1.6                  # rays that reach the ground first end there
    r[ground] = 1.6 / np.sin(-el[ground])
    pts = np.stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el),
                    rng.uniform(0.0, 1.0, n)], axis=1)
    pts.astype("<f4").tofile(out / "scan.bin")

    # Its calibration (KITTI object format): camera 2 = the demo's pinhole
    # at 48x32, Velodyne x forward -> camera z, y left -> -x, z up -> -y.
    f, cx, cy = FY, (W - 1) / 2, (H - 1) / 2
    (out / "kitti-calib.txt").write_text(
        f"P0: {f:.6f} 0 {cx} 0 0 {f:.6f} {cy} 0 0 0 1 0\n"
        f"P1: {f:.6f} 0 {cx} 0 0 {f:.6f} {cy} 0 0 0 1 0\n"
        f"P2: {f:.6f} 0 {cx} 0 0 {f:.6f} {cy} 0 0 0 1 0\n"
        f"P3: {f:.6f} 0 {cx} 0 0 {f:.6f} {cy} 0 0 0 1 0\n"
        "R0_rect: 1 0 0 0 1 0 0 0 1\n"
        "Tr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0\n"
        "Tr_imu_to_velo: 1 0 0 0 0 1 0 0 0 0 1 0\n")

    # A virtual object for insert: a tower at 300 m over the middle columns
    # (linear RGB, PFM: no alpha channel, so alpha 1 where its range is known).
    obj = np.zeros((H, W, 3))
    orange = np.full((H, W), np.nan)
    obj[2:28, 18:30] = (0.6, 0.3, 0.2)
    orange[2:28, 18:30] = 300.0
    write_pfm(out / "object.pfm", obj)
    write_pfm(out / "object-range.pfm", orange)

    # A scale map for blur: sigma from 1 px (left) to 4 px (right), a step in the middle rows.
    x = np.linspace(0.0, 1.0, W)[None, :].repeat(H, axis=0)
    x[H // 3:2 * H // 3] = np.where(np.arange(W) < W // 2, 0.1, 0.9)
    write_pfm(out / "scale.pfm", 1.0 + 3.0 * x)

    # The demo's range with a renderer's background (Cycles writes 1e10 where
    # no surface is hit) in place of its unknown sky.
    rng_m = read_pfm(range_pfm)
    write_pfm(out / "range-background.pfm", np.where(np.isfinite(rng_m), rng_m, 1e10))

    # A rectified stereo pair: a random texture, and in the right view the
    # same texture 3 px to the left (disparity 3 px everywhere), linear RGB.
    tex = rng.uniform(0.05, 0.95, (H, W + 3, 3))
    write_pfm(out / "left.pfm", tex[:, :W])
    write_pfm(out / "right.pfm", tex[:, 3:])


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
