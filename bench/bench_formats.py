#!/usr/bin/env python3
"""Whole runs through the table of formats: two brume builds alternated on the
same files, and brume's OpenEXR read and write phases against `oiiotool`'s
(issue #55 item 4).

The inputs are brume's demo scene (`brume demo`, 1600x1120 by default): its
colour image clean.png (8-bit), converted with oiiotool to a 16-bit PNG, a
JPEG (oiiotool's defaults: quality 98, 4:2:0), a 16-bit TIFF and a float
OpenEXR (zip), and its range map range.exr (one float channel, zip), which
every haze run reads. The space-variant blur's scale map is the haze's own
(`brume haze ... --scale-map s.exr`). Each round runs every case with both
builds, the order of the builds alternating from round to round:

  png8    haze clean.png    -> o.png          (the demo's haze: visibility 3000 m,
  png16   haze clean16.png  -> o.png --bits 16  albedo 0.9, lambda 6)
  jpeg    haze clean.jpg    -> o.jpg
  tiff16  haze clean16.tif  -> o.tif --bits 16
  exr     blur clean.exr --scale-map s.exr -> o.exr
  (and `brume --version`: the start-up every run pays)

and reports, per case, each build's whole-run wall time (median, min..max),
the median of the per-round ratios new/old, the medians of `--timing`'s
read, write and effect phases, and each process's CPU time (user + system, every
thread; from getrusage), which a loaded host disturbs less than the wall
time.

--peer: brume's OpenEXR phases against oiiotool's on the same file, same
compression (zip) and threads (--threads, default 2, the cores of the hosts
measured). The file e.exr is the float EXR blurred once (`brume blur --sigma
3`), so that what is read and what is written are alike (full float
mantissas: clean.exr's values, 8-bit codes, deflate four times smaller).
In each round, alternating which goes first, `brume blur --image e.exr
--sigma 3 --out b.exr --timing` (its read phase decodes e.exr and hashes the
file for the record; its write phase writes b.exr) and oiiotool twice:
`oiiotool --threads N --runstats e.exr --compression zip -o p.exr` for the
read (-i: the same file brume reads) and the same on b0.exr, the same
pixels as b.exr, for the write (-o: the pixels brume writes); oiiotool
times each command at 10 ms resolution.

  python3 bench/bench_formats.py --old /path/to/old/brume [--new build/brume]
                                 [--rounds 8] [--cases jpeg,png8,...] [--peer]

Not run by ctest. Prints the machine (lscpu's model, family and model), the
cores and the load before and after.
"""
import argparse
import os
import pathlib
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

from benchlib import cpu_model

ROOT = pathlib.Path(__file__).resolve().parent.parent
HAZE = ["--visibility", "3000", "--albedo", "0.9", "--lambda", "6"]
PHASES = re.compile(r"whole run .*read ([0-9.]+) ms .*effect ([0-9.]+) ms, write ([0-9.]+) ms")


def run(cmd):
    """Wall ms, CPU ms (user + system, all threads) and the output of one process."""
    u0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True)
    dt = (time.perf_counter() - t0) * 1000.0
    u1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        sys.exit(f"bench_formats: {' '.join(map(str, cmd))} failed ({r.returncode}):\n{r.stderr}")
    cpu = (u1.ru_utime - u0.ru_utime + u1.ru_stime - u0.ru_stime) * 1000.0
    return dt, cpu, r.stdout + r.stderr


def phases(text):
    """--timing's read, write and effect phases, in ms."""
    m = PHASES.search(text)
    return (float(m.group(1)), float(m.group(3)), float(m.group(2))) if m else (float("nan"),) * 3


def oiio_phases(text):
    """oiiotool --runstats' per-command seconds: -i (read) and -o (write), in ms."""
    got = {}
    for line in text.splitlines():
        m = re.match(r"\s+(-i|-o)\s+:\s+([0-9.]+)", line)
        if m:
            got[m.group(1)] = float(m.group(2)) * 1000.0
    return got.get("-i", float("nan")), got.get("-o", float("nan"))


def load():
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def med(v):
    return statistics.median(v)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--old", help="the build to compare against (its brume binary)")
    ap.add_argument("--new", default=str(ROOT / "build" / "brume"))
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--cases", default="png8,png16,jpeg,tiff16,exr")
    ap.add_argument("--peer", action="store_true", help="brume's OpenEXR phases against oiiotool's")
    ap.add_argument("--threads", type=int, default=2, help="oiiotool's --threads in --peer (brume uses all cores)")
    ap.add_argument("--width", type=int, default=1600)
    ap.add_argument("--height", type=int, default=1120)
    a = ap.parse_args()
    if not a.old and not a.peer:
        sys.exit("bench_formats: give --old BRUME (a build to compare with) and/or --peer")
    if not shutil.which("oiiotool"):
        sys.exit("bench_formats: needs oiiotool (Debian: openimageio-tools) to make the inputs")
    print(f"{cpu_model()}, {os.cpu_count()} cores; load before: {load()}")

    with tempfile.TemporaryDirectory(prefix="brume_formats_") as td:
        t = pathlib.Path(td)
        run([a.new, "demo", "--out-dir", t, "--width", a.width, "--height", a.height])
        run(["oiiotool", t / "clean.png", "-d", "uint16", "-o", t / "clean16.png"])
        run(["oiiotool", t / "clean.png", "-o", t / "clean.jpg"])
        run(["oiiotool", t / "clean.png", "-d", "uint16", "-o", t / "clean16.tif"])
        run(["oiiotool", t / "clean.png", "-d", "float", "--compression", "zip", "-o", t / "clean.exr"])
        rng = ["--range", t / "range.exr"]
        run([a.new, "haze", "--image", t / "clean.png", *rng, *HAZE, "--out", t / "h.pfm", "--scale-map", t / "s.exr"])
        run([a.new, "blur", "--image", t / "clean.exr", "--sigma", "3", "--out", t / "e.exr"])
        run([a.new, "blur", "--image", t / "e.exr", "--sigma", "3", "--out", t / "b0.exr"])  # what --peer's brume writes
        cases = {
            "png8": ("PNG -> PNG haze, 8-bit", ["haze", "--image", t / "clean.png", *rng, *HAZE], "o.png", []),
            "png16": ("PNG -> PNG haze, 16-bit", ["haze", "--image", t / "clean16.png", *rng, *HAZE], "o.png",
                      ["--bits", "16"]),
            "jpeg": ("JPEG -> JPEG haze", ["haze", "--image", t / "clean.jpg", *rng, *HAZE], "o.jpg", []),
            "tiff16": ("16-bit TIFF -> TIFF haze", ["haze", "--image", t / "clean16.tif", *rng, *HAZE], "o.tif",
                       ["--bits", "16"]),
            "exr": ("EXR -> EXR space-variant blur", ["blur", "--image", t / "clean.exr", "--scale-map", t / "s.exr"],
                    "o.exr", []),
        }
        chosen = [c for c in a.cases.split(",") if c]
        for c in chosen:
            if c not in cases:
                sys.exit(f"bench_formats: --cases: '{c}' is not one of {', '.join(cases)}")
        builds = [("old", a.old), ("new", a.new)] if a.old else []
        res = {(c, b): [] for c in chosen for b, _ in builds}
        peer = {k: [] for k in ("brume_exr", "oiio_exr")}
        startup = {b: [] for b, _ in builds}  # `brume --version`: loading and static initialisation
        for r in range(a.rounds):
            order = builds if r % 2 == 0 else builds[::-1]
            for b, exe in order:
                dt, cpu, _ = run([exe, "--version"])
                startup[b].append((dt, cpu))
            for c in chosen:
                _, args, out, extra = cases[c]
                for b, exe in order:
                    dt, cpu, text = run([exe, *args, "--out", t / f"{b}-{out}", *extra, "--timing"])
                    rd, wr, ef = phases(text)
                    res[(c, b)].append((dt, rd, wr, cpu, ef))
            if a.peer:
                for i in range(2):  # brume and oiiotool, alternating which goes first
                    if (r + i) % 2 == 0:
                        _, _, text = run([a.new, "blur", "--image", t / "e.exr", "--sigma", "3", "--out",
                                       t / "b.exr", "--timing"])
                        peer["brume_exr"].append(phases(text)[:2])
                    else:
                        _, _, text = run(["oiiotool", "--threads", a.threads, "--runstats", t / "e.exr",
                                       "--compression", "zip", "-o", t / "p.exr"])
                        read_ms = oiio_phases(text)[0]
                        _, _, text = run(["oiiotool", "--threads", a.threads, "--runstats", t / "b0.exr",
                                          "--compression", "zip", "-o", t / "q.exr"])
                        peer["oiio_exr"].append((read_ms, oiio_phases(text)[1]))

        print(f"{a.width} x {a.height}, {a.rounds} rounds; load after: {load()}")
        if builds:
            print(f"old: {a.old}\nnew: {a.new}")
            print("| run | old ms | new ms | ratio (median of rounds) | ratio range | read old -> new | write old -> new "
                  "| CPU ms old -> new | CPU ratio | effect old -> new |")
            print("| --- | ---: | ---: | ---: | --- | --- | --- | --- | ---: | --- |")
            for c in chosen:
                o, n = res[(c, "old")], res[(c, "new")]
                ratios = [y[0] / x[0] for x, y in zip(o, n)]
                print(f"| {cases[c][0]} | {med([x[0] for x in o]):.0f} ({min(x[0] for x in o):.0f}..{max(x[0] for x in o):.0f})"
                      f" | {med([x[0] for x in n]):.0f} ({min(x[0] for x in n):.0f}..{max(x[0] for x in n):.0f})"
                      f" | {med(ratios):.2f} | {min(ratios):.2f}..{max(ratios):.2f}"
                      f" | {med([x[1] for x in o]):.1f} -> {med([x[1] for x in n]):.1f}"
                      f" | {med([x[2] for x in o]):.1f} -> {med([x[2] for x in n]):.1f}"
                      f" | {med([x[3] for x in o]):.0f} -> {med([x[3] for x in n]):.0f}"
                      f" | {med([y[3] / x[3] for x, y in zip(o, n)]):.2f}"
                      f" | {med([x[4] for x in o]):.0f} -> {med([x[4] for x in n]):.0f} |")
            o, n = startup["old"], startup["new"]
            print(f"| `brume --version` (start-up) | {med([x[0] for x in o]):.0f} | {med([x[0] for x in n]):.0f}"
                  f" | {med([y[0] / x[0] for x, y in zip(o, n)]):.2f} | | | "
                  f"| {med([x[1] for x in o]):.0f} -> {med([x[1] for x in n]):.0f}"
                  f" | {med([y[1] / x[1] for x, y in zip(o, n)]):.2f} | |")
        if a.peer:
            print(f"OpenEXR phases, brume (all cores) against oiiotool --threads {a.threads}, zip, medians in ms:")
            print("| file | brume read | oiiotool -i | ratio | brume write | oiiotool -o | ratio |")
            print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
            sizes = ", ".join(f"{f} {(t / f).stat().st_size / 1e6:.2f} MB" for f in ("e.exr", "b.exr", "q.exr"))
            print(f"({sizes})")
            for name, b, o in (("e.exr (RGB float)", "brume_exr", "oiio_exr"),):
                br, bw = med([x[0] for x in peer[b]]), med([x[1] for x in peer[b]])
                orr, ow = med([x[0] for x in peer[o]]), med([x[1] for x in peer[o]])
                print(f"| {name} | {br:.1f} | {orr:.0f} | {br / orr:.2f} | {bw:.1f} | {ow:.0f} | {bw / ow:.2f} |")


if __name__ == "__main__":
    main()
