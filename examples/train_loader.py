#!/usr/bin/env python3
"""A torch training loader with brume's transforms: haze, then depth of field.

  PYTHONPATH=build/python /usr/bin/python3 examples/train_loader.py [--data ../shared/data] [--epochs 2]

A torch Dataset over the real frames of ../shared/data (read in place):
Middlebury 2005's six third-size scenes (disparity -> range by
brume.depth.convert) and KITTI object frame 000001 (its Velodyne scan
projected into the image). Each sample gets a Haze and a DepthOfField
transform, drawn per (seed, epoch, frame) -- key= -- so a DataLoader with two
workers draws exactly what one process would. The loader has two worker
processes, forked after the parent has run an effect (brume is fork-safe;
each worker runs brume with one thread). It prints each sample's drawn
parameters and writes a contact sheet PNG to examples/out/ (git-ignored: the
data's licences do not allow committing derived images).
"""
import argparse
import json
import pathlib
import sys

import numpy as np

import brume
from brume import transforms as T

try:
    import torch
    from torch.utils.data import DataLoader, Dataset
except ImportError:
    sys.exit("train_loader.py needs torch (apt-get install python3-torch; scripts/install-deps.sh)")

ROOT = pathlib.Path(__file__).resolve().parents[1]
F_THIRD_PX = 3740.0 / 3.0  # Middlebury 2005 full-size focal length, third-size images (data/SOURCES.md)
BASELINE_M = 0.160


def load_frames(data):
    """[(name, rgb float32 linear H x W x 3, range float32 metres, NaN unknown, kind)]."""
    frames = []
    mb = data / "middlebury2005_thirdsize"
    for scene in sorted(p for p in mb.iterdir() if (p / "view1.png").exists()) if mb.is_dir() else []:
        dmin = float((scene / "dmin.txt").read_text().split()[0])
        rng = brume.depth.convert(disparity=scene / "disp1.png", fx=F_THIRD_PX, baseline=BASELINE_M,
                                  disparity_scale=1.0 / 3.0, disparity_offset=dmin / 3.0).range
        frames.append((f"middlebury/{scene.name}", brume.read_image(scene / "view1.png").rgb, rng, "indoor"))
    k = data / "kitti_object_000001"
    if k.is_dir():
        rng = brume.depth.convert(velodyne=k / "velodyne" / "000001.bin", kitti_calib=k / "calib" / "000001.txt",
                                  like=k / "image_2" / "000001.png").range
        frames.append(("kitti/000001", brume.read_image(k / "image_2" / "000001.png").rgb, rng, "street"))
    return frames


class HazyFrames(Dataset):
    """Each item: (image tensor C x H x W float [0, 1], linear RGB; the drawn
    parameters as JSON). Distributions in physical units, per kind of scene:
    the Middlebury rooms span 1.4-2.9 m (visibility 8-80 m: a smoky room), the
    KITTI street 5-80 m (visibility 60-600 m: mist to haze)."""

    def __init__(self, frames, seed, epoch=0):
        self.frames, self.epoch = frames, epoch
        # The KITTI scan covers 4 % of the image: it is completed, guided by
        # the image (complete="auto", the default: docs/depth-sources.md).
        self.haze = {"indoor": T.Haze(visibility=T.loguniform(8, 80), lambda_=(1, 6), seed=seed),
                     "street": T.Haze(visibility=T.loguniform(60, 600), lambda_=(1, 6), seed=seed)}
        # (its own seed: two transforms with one seed and one key draw a parameter of the same name alike)
        self.dof = {"indoor": T.DepthOfField(focus_distance=(1.5, 3), f_number=T.choice(1.4, 2, 2.8), p=0.7,
                                             seed=seed + 1),
                    "street": T.DepthOfField(focus_distance=T.loguniform(5, 60), p=0.7, seed=seed + 1)}

    def __len__(self):
        return len(self.frames)

    def __getitem__(self, i):
        name, rgb, rng, kind = self.frames[i]
        key = f"epoch{self.epoch}/{name}"
        image = torch.from_numpy(np.ascontiguousarray(rgb.transpose(2, 0, 1)))  # C x H x W, linear
        a = self.haze[kind](image=image, depth=rng, key=key)
        b = self.dof[kind](image=a["image"], depth=rng, key=key)
        drawn = {"frame": name, "key": key, "haze": a["params"]["values"],
                 "dof": b["params"]["values"] if b["params"]["applied"] else None}
        return b["image"], json.dumps(drawn)


def contact_sheet(images, height=120):
    """Thumbnails (nearest sampling) side by side in rows of four, linear float H x W x 3."""
    thumbs = []
    for im in images:
        a = im.numpy().transpose(1, 2, 0)
        rows = (np.arange(height) * a.shape[0] / height).astype(int)
        w = max(1, int(round(a.shape[1] * height / a.shape[0])))
        cols = (np.arange(w) * a.shape[1] / w).astype(int)
        thumbs.append(a[rows][:, cols])
    per_row = 4
    lines = []
    for r in range(0, len(thumbs), per_row):
        line = thumbs[r:r + per_row]
        lines.append(np.concatenate(line, axis=1))
    width = max(x.shape[1] for x in lines)
    lines = [np.pad(x, ((0, 0), (0, width - x.shape[1]), (0, 0))) for x in lines]
    return np.ascontiguousarray(np.concatenate(lines, axis=0), dtype=np.float32)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--data", type=pathlib.Path, default=ROOT.parent / "shared" / "data")
    ap.add_argument("--out-dir", type=pathlib.Path, default=ROOT / "examples" / "out")
    ap.add_argument("--epochs", type=int, default=1)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    if not a.data.is_dir():
        print(f"train_loader.py: the data folder {a.data} is absent; nothing to do (skipped)")
        return
    frames = load_frames(a.data)
    if not frames:
        print(f"train_loader.py: no Middlebury or KITTI frames under {a.data} (skipped)")
        return
    # brume ran in this process (load_frames) before the workers fork: it is fork-safe (docs/transforms.md).
    shown = []
    for epoch in range(a.epochs):
        loader = DataLoader(HazyFrames(frames, a.seed, epoch), batch_size=None, num_workers=2,
                            multiprocessing_context="fork")
        for image, drawn in loader:
            print(drawn)
            shown.append(image)
    a.out_dir.mkdir(parents=True, exist_ok=True)
    out = a.out_dir / "contact_sheet.png"
    brume.write_image(out, contact_sheet(shown), bits="8")
    print(f"wrote {out} ({len(shown)} samples)")


if __name__ == "__main__":
    main()
