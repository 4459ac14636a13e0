#!/usr/bin/env python3
"""Augment Middlebury 2005 frames with haze, on a thread pool.

  PYTHONPATH=build/python python3 examples/augment_middlebury.py \
      --data ../shared/data/middlebury2005_thirdsize --out-dir aug --variants 4 --workers 2

For every scene folder (view1.png, disp1.png, dmin.txt) the disparity becomes
a range map once (brume.depth.convert: d = I/3 + dmin/3 px at f = 3740/3 px,
B = 160 mm, I = 0 unknown), then each variant draws its haze parameters and
runs brume.haze with threads=1 -- the parallelism is the pool's: brume
releases the GIL, so N workers keep N cores busy. Each output is a PNG with
its parameter record embedded, and the record beside it as JSON.

Parameters are drawn per (seed, frame, variant) -- not in call order -- so a
rerun, or any subset of frames, gets the same values for the same frame.
"""
import argparse
import json
import pathlib
import sys
import time
from concurrent.futures import ThreadPoolExecutor, as_completed

import brume

F_THIRD_PX = 3740.0 / 3.0  # full-size focal length, third-size images (data/SOURCES.md)
BASELINE_M = 0.160


def load_scene(folder):
    rgb = brume.read_image(folder / "view1.png").rgb
    dmin = float((folder / "dmin.txt").read_text().split()[0])
    rng = brume.depth.convert(disparity=folder / "disp1.png", fx=F_THIRD_PX, baseline=BASELINE_M,
                              disparity_scale=1.0 / 3.0, disparity_offset=dmin / 3.0).range
    return rgb, rng


SPECS = {"visibility": "loguniform(8, 80)", "albedo": "uniform(0.8, 1)", "lambda": "uniform(1, 8)"}


def draw_params(seed, key):
    """Haze parameters for one output, from (seed, key) alone."""
    # The library's sampler, keyed by (seed, frame key, parameter name): the
    # same values as `brume sample` and the batch mode, whatever the order.
    # The scenes span 1.4-2.9 m: visibilities of 8-80 m give optical depths of
    # about 0.1-1 at the back wall (a smoky room); log-uniform, as visibility spans decades.
    return brume.random_params("haze", seed, key, **SPECS)


def main():
    root = pathlib.Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--data", type=pathlib.Path, default=root.parent / "shared" / "data" / "middlebury2005_thirdsize")
    ap.add_argument("--out-dir", type=pathlib.Path, required=True)
    ap.add_argument("--variants", type=int, default=4, help="hazy variants per frame")
    ap.add_argument("--workers", type=int, default=2, help="threads in the pool (each call uses threads=1)")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()

    scenes = sorted(p for p in a.data.iterdir() if (p / "view1.png").exists() and (p / "disp1.png").exists())
    if not scenes:
        sys.exit(f"no Middlebury scene folders (view1.png, disp1.png, dmin.txt) in {a.data}")
    a.out_dir.mkdir(parents=True, exist_ok=True)
    frames = {s.name: load_scene(s) for s in scenes}  # read once, shared read-only by the workers

    def job(name, k):
        key = f"{name}/{k}"
        params = draw_params(a.seed, key)
        rgb, rng = frames[name]
        r = brume.haze(rgb, rng, threads=1, **params)
        # How the values were drawn, so the record reproduces them (brume sample prints the same).
        r.record["sampling"] = {"sampler": "brume-sample-v1", "seed": a.seed, "key": key, "specs": SPECS}
        out = a.out_dir / f"{name}_{k:03d}.png"
        brume.write_image(out, r.rgb, bits="8", record=r.record)
        out.with_suffix(".json").write_text(json.dumps(r.record, indent=2) + "\n")
        return out

    tasks = [(name, k) for name in frames for k in range(a.variants)]
    t0 = time.perf_counter()
    done = 0
    with ThreadPoolExecutor(max_workers=a.workers) as pool:
        futures = [pool.submit(job, *t) for t in tasks]
        for f in as_completed(futures):
            f.result()  # re-raises a worker's error
            done += 1
            el = time.perf_counter() - t0
            rate = done / el
            eta = (len(tasks) - done) / rate
            bar = "#" * (30 * done // len(tasks))
            print(f"\r[{bar:<30}] {done}/{len(tasks)}  {rate:.2f} img/s  ETA {eta:4.0f} s", end="", file=sys.stderr,
                  flush=True)
    print(f"\nwrote {len(tasks)} images and records to {a.out_dir} in {time.perf_counter() - t0:.1f} s",
          file=sys.stderr)


if __name__ == "__main__":
    main()
