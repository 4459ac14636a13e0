#!/usr/bin/env python3
"""A range map (1-channel PFM, metres, NaN unknown) as a picture for the docs:
colour by inverse range (matplotlib's turbo, near red, far blue; 1/R keeps
the near scene's detail), unknown pixels black; --dilate N widens each known
pixel of a sparse map to (2N+1)² so that a projected scan is visible.

  python3 scripts/range_picture.py IN.pfm OUT.jpg [--near 4] [--far 80] [--dilate 0]
"""
import argparse

import numpy as np
from matplotlib import cm
from PIL import Image


def read_pfm(path):
    with open(path, "rb") as f:
        kind = f.readline().strip()
        if kind != b"Pf":
            raise SystemExit(f"{path}: not a 1-channel PFM (header {kind!r})")
        w, h = (int(v) for v in f.readline().split())
        scale = float(f.readline())
        data = np.frombuffer(f.read(4 * w * h), dtype="<f4" if scale < 0 else ">f4")
    return data.reshape(h, w)[::-1].astype(np.float32)  # PFM rows run bottom to top


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("src")
    ap.add_argument("out")
    ap.add_argument("--near", type=float, default=4.0, help="range [m] at the red end")
    ap.add_argument("--far", type=float, default=80.0, help="range [m] at the blue end")
    ap.add_argument("--dilate", type=int, default=0, help="widen each known pixel by N px")
    a = ap.parse_args()
    r = read_pfm(a.src)
    known = np.isfinite(r) & (r > 0)
    inv = np.where(known, 1.0 / np.where(known, r, 1.0), 0.0)
    if a.dilate > 0:  # the nearest return wins where widened pixels meet
        n = a.dilate
        pad = np.pad(inv, n)
        wide = np.zeros_like(inv)
        for dy in range(2 * n + 1):
            for dx in range(2 * n + 1):
                wide = np.maximum(wide, pad[dy:dy + inv.shape[0], dx:dx + inv.shape[1]])
        inv, known = wide, wide > 0
    t = np.clip((inv - 1.0 / a.far) / (1.0 / a.near - 1.0 / a.far), 0.0, 1.0)
    rgb = (cm.turbo(t)[..., :3] * 255.0 + 0.5).astype(np.uint8)
    rgb[~known] = 0
    Image.fromarray(rgb).save(a.out, quality=85)


if __name__ == "__main__":
    main()
