#!/usr/bin/env python3
"""Whole `brume blur` runs, PFM in and PFM out, against a one-shot OpenCV
process on the same file (issue #16's whole-run targets).

The input is brume's demo scene at 1600x1120 (linear RGB float, written as a
PFM through the Python module), and a haze-like scale map from its range:
sigma = 25 (1 - exp(-3 r / r_max)), at least 1 px, 25 px for sky. Each round
runs, in an order that rotates from round to round:

  constant:      brume blur --image i.pfm --sigma 25 --out o.pfm
  space-variant: brume blur --image i.pfm --scale-map s.pfm --out o.pfm
  peer:          brume_oneshot_gaussian i.pfm 25 o.pfm  (bench/oneshot_gaussian.cpp:
                 raw PFM I/O and cv::GaussianBlur, 201 taps; what
                 `python3 -c "import cv2; ..."` does without the interpreter's
                 start-up and cv2's import, so a stricter peer than the script)

and reports each command's wall time (median, min..max over the rounds) and
the ratios to the peer within each round (median). Every process pays its
own start-up: brume's 0.36-0.39 s of dynamic loading (docs/performance.md) is
part of what is compared, as it is part of what a user waits for.

  python3 bench/bench_whole_run.py [--cli build/brume] [--peer build/bench/brume_oneshot_gaussian]
                                   [--rounds 7] [--width 1600 --height 1120]

Needs the brume_cli, brume_python and brume_oneshot_gaussian targets. Not
run by ctest. Prints the machine (lscpu model name, cores) and the load.
"""
import argparse
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time
from benchlib import cpu_model


ROOT = pathlib.Path(__file__).resolve().parent.parent




def timed(cmd):
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        sys.exit(f"bench_whole_run: {' '.join(map(str, cmd))} failed ({r.returncode}):\n{r.stderr}")
    return dt


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cli", default=str(ROOT / "build" / "brume"))
    ap.add_argument("--peer", default=str(ROOT / "build" / "bench" / "brume_oneshot_gaussian"))
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--width", type=int, default=1600)
    ap.add_argument("--height", type=int, default=1120)
    a = ap.parse_args()
    sys.path.insert(0, str(ROOT / "build" / "python"))
    import numpy as np
    import brume

    with tempfile.TemporaryDirectory(prefix="brume_whole_run_") as td:
        tmp = pathlib.Path(td)
        subprocess.run([a.cli, "demo", "--out-dir", str(tmp), "--width", str(a.width), "--height", str(a.height)],
                       check=True, capture_output=True)
        rgb = brume.read_image(str(tmp / "clean.png")).rgb
        brume.write_image(str(tmp / "i.pfm"), np.ascontiguousarray(rgb, dtype=np.float32))
        r = brume.read_image(str(tmp / "range.exr"), transfer="linear").rgb[..., 0].astype(np.float64)
        known = np.isfinite(r) & (r > 0)
        rmax = r[known].max()
        s = np.where(known, 25.0 * (1.0 - np.exp(-3.0 * np.where(known, r, 0.0) / rmax)), 25.0)
        s = np.clip(s, 1.0, 25.0).astype(np.float32)
        brume.write_image(str(tmp / "s.pfm"), s)
        cmds = {
            "brume blur --sigma 25 (constant)": [a.cli, "blur", "--image", str(tmp / "i.pfm"), "--sigma", "25",
                                                 "--out", str(tmp / "o_c.pfm")],
            "brume blur --scale-map (space-variant, sigma <= 25)": [a.cli, "blur", "--image", str(tmp / "i.pfm"),
                                                                    "--scale-map", str(tmp / "s.pfm"),
                                                                    "--out", str(tmp / "o_v.pfm")],
            "one-shot OpenCV GaussianBlur sigma 25 (peer)": [a.peer, str(tmp / "i.pfm"), "25", str(tmp / "o_p.pfm")],
        }
        names = list(cmds)
        peer = names[2]
        for n in names:  # warm the page cache and the dynamic loader's files
            timed(cmds[n])
        times = {n: [] for n in names}
        ratios = {n: [] for n in names[:2]}
        for k in range(a.rounds):
            order = names[k % 3:] + names[:k % 3]
            t = {n: timed(cmds[n]) for n in order}
            for n in names:
                times[n].append(t[n])
            for n in names[:2]:
                ratios[n].append(t[n] / t[peer])
        load = os.getloadavg()[0]
        print(f"# bench_whole_run\n\n- machine: {cpu_model()}, {os.cpu_count()} cores, load {load:.2f}")
        print(f"- image: {a.width}x{a.height} RGB float PFM; {a.rounds} interleaved rounds after a warm-up\n")
        print("| command | wall ms, median (min..max) | vs peer, median of rounds |")
        print("|---|---:|---:|")
        for n in names:
            ms = [1000 * x for x in times[n]]
            rt = f"**{statistics.median(ratios[n]):.2f}×**" if n in ratios else "1.00×"
            print(f"| {n} | {statistics.median(ms):.0f} ({min(ms):.0f}..{max(ms):.0f}) | {rt} |")


if __name__ == "__main__":
    main()
