"""`brume batch` on a Dask cluster: one task per frame (issue #17).

    python3 -m brume.dask --manifest FILE --out-dir DIR --scheduler ADDRESS|local
                          [--workers N] [--seed S] [--format EXT] [--effect E] [--param NAME=SPEC]...
                          [--map NAME]... [--resume] [--threads T]

The manifest is planned here, by the library's own planner (the code `brume
batch` runs: the same columns, checks, sampled values, output names and
records), and each frame is a Dask task that runs it through the effect's
pipeline in the worker, the GIL released. So the outputs are those of `brume
batch` with the same options, bit for bit, and the records equal apart from
time and timings (argv holds the same output-deciding options; --threads is
recorded, so give the CLI the same value to compare records).

`--scheduler local` starts a LocalCluster of --workers processes with one
thread each; an ADDRESS (tcp://host:8786) uses a running scheduler, whose
workers must import this `brume` package and read the manifest's files and
--out-dir at the same paths. The results manifest is <out-dir>/results.jsonl,
one line per frame in manifest order, written whole at the end. Exit status:
0 every frame done, 1 some failed, 2 nothing could run.
"""
import argparse
import json
import os
import sys
import time

from . import _brume


def plan(manifest, out_dir, seed=0, format="", effect="", params=(), maps=()):
    """(argv for the records, [frame JSON text, ...]) of a manifest, as `brume batch` plans it."""
    p = json.loads(_brume._batch_plan(str(manifest), str(out_dir), int(seed), format, effect,
                                      [tuple(x) for x in params], list(maps)))
    return p["argv"], [json.dumps(f) for f in p["frames"]]


def run_frame(frame, argv, threads=1):
    """The Dask task: one planned frame through its pipeline; returns its results line (a dict)."""
    from brume import _brume as b  # imported in the worker
    return json.loads(b._batch_run_frame(frame, list(argv), int(threads)))


def _skipped_line(frame):
    f = json.loads(frame)
    return {"key": f["key"], "status": "skipped", "effect": f["effect"], "seconds": 0.0,
            "outputs": {"image": f["outputs"][0], "record": f["outputs"][-1]},
            "sampling": f["batch"]["sampling"]}


def run(client, manifest, out_dir, *, seed=0, format="", effect="", params=(), maps=(), resume=False, threads=1,
        progress=True):
    """Runs a manifest's frames as Dask tasks on `client`; returns the results lines in manifest order
    and writes <out_dir>/results.jsonl."""
    from distributed import as_completed

    argv, frames = plan(manifest, out_dir, seed, format, effect, params, maps)
    os.makedirs(out_dir, exist_ok=True)
    lines = [None] * len(frames)
    futures = {}
    for i, f in enumerate(frames):
        if resume and _brume._batch_frame_done(f):
            lines[i] = _skipped_line(f)
            continue
        # pure=False: a frame writes files, so Dask must run it even when an identical task ran before.
        futures[client.submit(run_frame, f, argv, threads, pure=False, key=f"brume-frame-{i}")] = i
    t0, done = time.monotonic(), 0
    for fut in as_completed(list(futures)):
        i = futures[fut]
        lines[i] = fut.result()
        done += 1
        if lines[i]["status"] == "failed":
            print(f"brume.dask: frame '{lines[i]['key']}' failed: {lines[i].get('error', '')}", file=sys.stderr)
        if progress:
            rate = done / max(time.monotonic() - t0, 1e-9)
            print(f"brume.dask: {done}/{len(futures)} frames  {rate:.2f} frames/s  "
                  f"ETA {(len(futures) - done) / rate:.0f} s", file=sys.stderr, flush=True)
    path = os.path.join(out_dir, "results.jsonl")
    tmp = os.path.join(out_dir, f".results.jsonl.brume-tmp-{os.getpid()}")
    with open(tmp, "w") as fh:
        fh.write("".join(json.dumps(l, sort_keys=True) + "\n" for l in lines))
    os.replace(tmp, path)
    return lines


def main(args=None):
    ap = argparse.ArgumentParser(prog="python3 -m brume.dask", description=__doc__.split("\n\n")[0])
    ap.add_argument("--manifest", required=True)
    ap.add_argument("--out-dir", required=True)
    ap.add_argument("--scheduler", required=True, help="ADDRESS of a running scheduler, or 'local'")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="local: worker processes")
    ap.add_argument("--threads", type=int, default=1, help="threads per frame (results do not depend on them)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--format", default="")
    ap.add_argument("--effect", default="")
    ap.add_argument("--param", action="append", default=[], help="NAME=SPEC for rows without that column")
    ap.add_argument("--map", action="append", default=[])
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--quiet", action="store_true")
    a = ap.parse_args(args)
    params = []
    for p in a.param:
        if "=" not in p or p.startswith("="):
            print(f"brume.dask: error: --param '{p}' is not NAME=SPEC", file=sys.stderr)
            return 2
        params.append(tuple(p.split("=", 1)))
    from distributed import Client, LocalCluster

    try:
        if a.scheduler == "local":
            cluster = LocalCluster(n_workers=a.workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None)
            client = Client(cluster)
        else:
            cluster, client = None, Client(a.scheduler)
        try:
            t0 = time.monotonic()
            lines = run(client, a.manifest, a.out_dir, seed=a.seed, format=a.format, effect=a.effect, params=params,
                        maps=a.map, resume=a.resume, threads=a.threads, progress=not a.quiet)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    except ValueError as e:
        print(f"brume.dask: error: {e}", file=sys.stderr)
        return 2
    n = {s: sum(1 for l in lines if l["status"] == s) for s in ("ok", "skipped", "failed")}
    print(f"brume.dask: {len(lines)} frames in {time.monotonic() - t0:.1f} s: {n['ok']} done, "
          f"{n['skipped']} skipped (done before), {n['failed']} failed", file=sys.stderr)
    return 1 if n["failed"] else 0


if __name__ == "__main__":
    sys.exit(main())
