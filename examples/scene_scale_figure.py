#!/usr/bin/env python3
"""The figure of docs/transforms.md's "Scenes at any scale": one Haze draw
(seed 3, the sampler's default distributions) on a room (Middlebury 2005 Art,
median range 1.8 m), a courtyard (ETH3D terrace, 4.2 m) and the demo's
street (8.3 m), in metres as drawn and scaled to each frame with
scene_scale=15; each panel says its transmission at the frame's median range.

    PYTHONPATH=build/python python3 examples/scene_scale_figure.py --data ../shared/data \\
        --out docs/images/scene-scale.png

Reads the data in place; writes one PNG (about 0.3 MB at the default height).
"""
import argparse
import math
import pathlib
import subprocess
import sys
import tempfile

import numpy as np

import brume
from brume import transforms as T

ROOT = pathlib.Path(__file__).resolve().parents[1]


def frames(data, brume_cli):
    """[(label, linear rgb, range in metres)]."""
    out = []
    art = data / "middlebury2005_thirdsize" / "Art"
    dmin = float((art / "dmin.txt").read_text().split()[0])
    out.append(("Middlebury Art (a room)", brume.read_image(art / "view1.png").rgb,
                brume.depth.convert(disparity=art / "disp1.png", fx=3740 / 3, baseline=0.16, disparity_scale=1 / 3,
                                    disparity_offset=dmin / 3).range))
    ter = data / "eth3d_two_view" / "terrace"
    out.append(("ETH3D terrace", brume.read_image(ter / "im0.png").rgb,
                brume.depth.convert(disparity=ter / "disp0.pfm", calib=ter / "calib.txt").range))
    tmp = pathlib.Path(tempfile.mkdtemp())
    subprocess.run([brume_cli, "demo", "--out-dir", str(tmp), "--width", "640", "--height", "448"], check=True,
                   stderr=subprocess.DEVNULL)
    out.append(("the demo's street", brume.read_image(tmp / "clean.png").rgb,
                brume.depth.convert(range=tmp / "range.exr").range))
    return out


def thumb(rgb, height):
    """Nearest-sampled to `height` rows, sRGB-encoded uint8."""
    rows = (np.arange(height) * rgb.shape[0] / height).astype(int)
    w = max(1, int(round(rgb.shape[1] * height / rgb.shape[0])))
    cols = (np.arange(w) * rgb.shape[1] / w).astype(int)
    a = np.clip(rgb[rows][:, cols], 0, 1)
    a = np.where(a <= 0.0031308, 12.92 * a, 1.055 * a ** (1 / 2.4) - 0.055)
    return (a * 255 + 0.5).astype(np.uint8)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=pathlib.Path, default=ROOT.parent / "shared" / "data")
    ap.add_argument("--out", type=pathlib.Path, default=ROOT / "docs" / "images" / "scene-scale.png")
    ap.add_argument("--brume", default=str(ROOT / "build" / "brume"))
    ap.add_argument("--height", type=int, default=150)
    ap.add_argument("--key", default="frame/9")  # a draw of 171 m: T(15 m) = 0.71
    a = ap.parse_args()
    try:
        from PIL import Image, ImageDraw
    except ImportError:
        sys.exit("scene_scale_figure.py needs python3-pil")
    plain, scaled = T.Haze(seed=3), T.Haze(seed=3, scene_scale=15)
    v = brume.random_params("haze", 3, a.key)
    rows = []
    for label, rgb, rng in frames(a.data, a.brume):
        med = float(np.median(rng[np.isfinite(rng) & (rng > 0)]))
        p = plain(image=rgb, depth=rng, key=a.key)
        s = scaled(image=rgb, depth=rng, key=a.key)
        applied = s["params"]["record"]["scene_scale"]["scaled"]["visibility"]["applied"]
        cells = [(thumb(rgb, a.height), [label, f"median range {med:.1f} m"]),
                 (thumb(p["image"], a.height), [f"as drawn: visibility {v['visibility']:.0f} m",
                                                f"T(median) {math.exp(-3.912 * med / v['visibility']):.2f}"]),
                 (thumb(s["image"], a.height), [f"scene_scale=15: visibility {applied:.1f} m",
                                                f"T(median) {math.exp(-3.912 * med / applied):.2f}"])]
        rows.append(cells)
    pad, text_h = 4, 28
    width = max(sum(c[0].shape[1] for c in r) + pad * (len(r) + 1) for r in rows)
    height = len(rows) * (a.height + text_h + pad) + pad
    sheet = Image.new("RGB", (width, height), (34, 34, 34))
    draw = ImageDraw.Draw(sheet)
    y = pad
    for r in rows:
        x = pad
        for img, caption in r:
            sheet.paste(Image.fromarray(img), (x, y + text_h))
            for i, line in enumerate(caption):
                draw.text((x + 2, y + 2 + 12 * i), line, fill=(230, 230, 230))
            x += img.shape[1] + pad
        y += a.height + text_h + pad
    a.out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(a.out, optimize=True)
    print(f"wrote {a.out} ({a.out.stat().st_size // 1024} kB); the draw: {v}")


if __name__ == "__main__":
    main()
