#!/usr/bin/env python3
"""brume batch against a shell loop of single `brume haze` runs (issue #17).

30 Middlebury 2005 third-size frames (463x370 / 447x370: the six scenes of
../shared/data, five keys each) with haze and sampled parameters; the same
frames, the same values, in the same rounds, interleaved:

  loop:  one `brume haze` process per frame, one after the other (what a shell
         script does today: process start-up, decode, effect, encode);
  batch: one `brume batch --workers W` process for the 30 frames.

Reports frames/s of each and their ratio (median of the rounds), and the
batch's per-frame overhead beyond the effect's own time:

  overhead = (batch --workers 1 --threads 1 wall / frames) / (effect's own time per frame) - 1,

both one frame after the other on one thread (on a shared machine, W
workers do not get W cores, so the parallel run's core time would charge the
neighbours' load to the batch), the effect's own time being brume.haze (run_haze: analysis, preparation of
the range, apply) on the frame's arrays already in memory, threads=1, one
frame after the other, in the same round (the Python module from
build/python). What the overhead holds: decoding the PNG and the disparity,
the disparity-to-range conversion, SHA-256 of the inputs, encoding, the
record, the rename. With python3-distributed installed, the same frames also
run through `python3 -m brume.dask --scheduler local --workers W`.

The overhead is measured at brume batch's PNG default (rle: the Up filter and
deflate's run-length strategy; zip:1 until 2026-12-02) and, in the same
rounds, at each --compression given (default zip:6, libpng's default, which
single runs keep; add zip:1 to compare with the old batch default), so that
the price of each is read side by side.

  python3 bench/bench_batch.py [--cli build/brume] [--rounds 3] [--workers 2] [--compression zip:6 ...]

Not run by ctest. Prints the machine (lscpu model name, cores) and the load.
"""
import argparse
import json
import os
import pathlib
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from benchlib import cpu_model


ROOT = pathlib.Path(__file__).resolve().parent.parent




def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cli", default=str(ROOT / "build" / "brume"))
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data" / "middlebury2005_thirdsize"))
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--compression", nargs="*", default=["zip:6"],
                    help="also measure the overhead with --param compression=SPEC (each, same rounds)")
    a = ap.parse_args()
    cli = pathlib.Path(a.cli)
    if not cli.exists():
        sys.exit(f"no brume CLI at {cli}; build the brume_cli target first")
    data = pathlib.Path(a.data)
    scenes = sorted(p for p in data.iterdir() if (p / "view1.png").exists()) if data.exists() else []
    if not scenes:
        sys.exit(f"no Middlebury scenes in {data}")

    tmp = pathlib.Path(tempfile.mkdtemp(prefix="brume_bench_batch_"))
    try:
        # The manifest: scan the folder, then give each scene several keys.
        subprocess.run([str(cli), "batch", "--dataset", str(data), "--layout", "middlebury",
                        "--manifest", str(tmp / "scan.jsonl")], check=True, capture_output=True)
        base = [json.loads(l) for l in (tmp / "scan.jsonl").read_text().splitlines()]
        rows = []
        for i in range(a.frames):
            r = dict(base[i % len(base)])
            r["key"] = f"{r['key'][:-4]}-{i // len(base)}.png"
            r.update({"effect": "haze", "visibility": "loguniform(2, 20)", "albedo": "uniform(0.8, 1)",
                      "lambda": "uniform(2, 8)"})
            rows.append(r)
        manifest = tmp / "frames.jsonl"
        manifest.write_text("".join(json.dumps(r) + "\n" for r in rows))

        # The loop needs the drawn values: one batch run first gives them (its records).
        subprocess.run([str(cli), "batch", "--manifest", str(manifest), "--out-dir", str(tmp / "plan"),
                        "--seed", "1", "--quiet"], check=True, capture_output=True)
        loop_cmds = []
        for r in rows:
            rec = json.loads((tmp / "plan" / (r["key"][:-4] + ".json")).read_text())
            h, d = rec["job"]["haze"], rec["job"]["depth"]
            cmd = [str(cli), "haze", "--image", str(tmp / r["image"]), "--disparity", str(tmp / r["disparity"]),
                   "--fx", repr(d["fx"]), "--baseline", repr(d["baseline"]),
                   "--disparity-scale", repr(d["disparity-scale"]), "--disparity-offset", repr(d["disparity-offset"]),
                   "--visibility", repr(h["visibility"]), "--albedo", repr(h["albedo"]), "--lambda", repr(h["lambda"])]
            loop_cmds.append((cmd, r["key"][:-4].replace("/", "_") + ".png"))
        shutil.rmtree(tmp / "plan")

        sys.path.insert(0, str(ROOT / "build" / "python"))
        try:
            import brume
        except ImportError as e:
            sys.exit(f"the brume Python module is not built in build/python ({e}); build target brume_python")
        try:
            import distributed  # noqa: F401
            have_dask = True
        except ImportError:
            have_dask = False
        # The frames' arrays, decoded once (outside every timing), for the effect's own time.
        arrays = {}
        for r in rows:
            if r["image"] in arrays:
                continue
            rgb = brume.read_image(str(tmp / r["image"])).rgb
            rng = brume.depth.convert(disparity=str(tmp / r["disparity"]), fx=r["fx"], baseline=r["baseline"],
                                      disparity_scale=r["disparity-scale"],
                                      disparity_offset=r["disparity-offset"]).range
            arrays[r["image"]] = (rgb, rng)
        values = []
        for cmd, _ in loop_cmds:
            v = {cmd[i][2:]: float(cmd[i + 1]) for i in range(len(cmd)) if cmd[i] in ("--visibility", "--albedo", "--lambda")}
            values.append(v)

        loop_fps, batch_fps, dask_fps, overheads, effect_ms = [], [], [], [], []
        comp_overheads = {c: [] for c in a.compression}
        for rnd in range(a.rounds):
            out = tmp / "loop"
            out.mkdir()
            t0 = time.perf_counter()
            for cmd, name in loop_cmds:
                subprocess.run(cmd + ["--out", str(out / name)], check=True, capture_output=True)
            loop_fps.append(len(rows) / (time.perf_counter() - t0))
            shutil.rmtree(out)

            out = tmp / "batch"
            t0 = time.perf_counter()
            subprocess.run([str(cli), "batch", "--manifest", str(manifest), "--out-dir", str(out), "--seed", "1",
                            "--workers", str(a.workers), "--quiet"], check=True, capture_output=True)
            wall = time.perf_counter() - t0
            batch_fps.append(len(rows) / wall)
            shutil.rmtree(out)

            t0 = time.perf_counter()
            for r, v in zip(rows, values):
                rgb, rng = arrays[r["image"]]
                brume.haze(rgb, rng, threads=1, **v)
            mean_eff = (time.perf_counter() - t0) / len(rows)
            effect_ms.append(mean_eff * 1000)
            out = tmp / "seq"
            t0 = time.perf_counter()
            subprocess.run([str(cli), "batch", "--manifest", str(manifest), "--out-dir", str(out), "--seed", "1",
                            "--workers", "1", "--threads", "1", "--quiet"], check=True, capture_output=True)
            seq = (time.perf_counter() - t0) / len(rows)
            shutil.rmtree(out)
            overheads.append(seq / mean_eff - 1.0)
            comp_txt = ""
            for c in a.compression:
                t0 = time.perf_counter()
                subprocess.run([str(cli), "batch", "--manifest", str(manifest), "--out-dir", str(out), "--seed", "1",
                                "--workers", "1", "--threads", "1", "--quiet", "--param", "compression=" + c],
                               check=True, capture_output=True)
                seq_c = (time.perf_counter() - t0) / len(rows)
                shutil.rmtree(out)
                comp_overheads[c].append(seq_c / mean_eff - 1.0)
                comp_txt += f", with compression {c} {comp_overheads[c][-1] * 100:.0f} %"

            dask_txt = ""
            if have_dask:
                out = tmp / "dask"
                env = dict(os.environ, PYTHONPATH=str(ROOT / "build" / "python"))
                t0 = time.perf_counter()
                subprocess.run([sys.executable, "-m", "brume.dask", "--manifest", str(manifest), "--out-dir", str(out),
                                "--scheduler", "local", "--workers", str(a.workers), "--seed", "1", "--quiet"],
                               check=True, capture_output=True, env=env)
                dask_fps.append(len(rows) / (time.perf_counter() - t0))
                shutil.rmtree(out)
                dask_txt = f", dask {dask_fps[-1]:.2f} frames/s (cluster start-up included)"
            print(f"round {rnd + 1}: loop {loop_fps[-1]:.2f} frames/s, batch {batch_fps[-1]:.2f} frames/s "
                  f"({batch_fps[-1] / loop_fps[-1]:.2f}x){dask_txt}, effect {mean_eff * 1000:.1f} ms/frame, "
                  f"batch --workers 1 overhead {overheads[-1] * 100:.0f} %{comp_txt}", flush=True)

        lf, bf = statistics.median(loop_fps), statistics.median(batch_fps)
        print(f"\n{cpu_model()}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}; "
              f"{len(rows)} Middlebury third-size frames, haze, batch --workers {a.workers}")
        print(f"loop of brume haze: {lf:.2f} frames/s   brume batch: {bf:.2f} frames/s   ratio {bf / lf:.2f}x "
              f"(target >= 3x)")
        if dask_fps:
            print(f"python3 -m brume.dask --scheduler local --workers {a.workers}: "
                  f"{statistics.median(dask_fps):.2f} frames/s")
        print(f"batch per-frame overhead beyond the effect's own time: {statistics.median(overheads) * 100:.0f} % "
              f"(effect {statistics.median(effect_ms):.1f} ms/frame; target <= 25 %)")
        for c, o in comp_overheads.items():
            print(f"  the same with --param compression={c}: {statistics.median(o) * 100:.0f} % "
                  f"(rounds {', '.join(f'{x * 100:.0f}' for x in o)} %)")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
