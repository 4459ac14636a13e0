"""brume.dask (issue #17): a manifest's frames as Dask tasks on a LocalCluster
of 2 worker processes give `brume batch`'s outputs bit for bit, and records
equal apart from time, timings and the output folder's name."""
import json
import os
import pathlib

import numpy as np
import pytest

from conftest import require_data, run_cli

distributed = pytest.importorskip("distributed", reason="python3-distributed (Debian) is not installed")


def _records_equal(a_dir, b_dir, rel):
    def load(d):
        t = (d / rel).read_text().replace(str(d), "OUT")
        r = json.loads(t)
        r.pop("time_utc", None)
        r["execution"].pop("timing", None)
        return r
    return load(a_dir) == load(b_dir)


def test_dask_local_cluster_equals_brume_batch(tmp_path, data_dir):
    import brume
    import brume.dask
    mb = require_data(data_dir / "middlebury2005_thirdsize")
    manifest = tmp_path / "m.jsonl"
    run_cli("batch", "--dataset", mb, "--layout", "middlebury", "--manifest", manifest)
    rows = [json.loads(l) for l in manifest.read_text().splitlines()][:3]
    for r in rows:
        r.update({"effect": "haze", "visibility": "loguniform(2, 20)", "lambda": "uniform(2, 6)"})
    manifest.write_text("".join(json.dumps(r) + "\n" for r in rows))

    run_cli("batch", "--manifest", manifest, "--out-dir", tmp_path / "cli", "--seed", 4, "--threads", 1, "--quiet")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        assert len(client.scheduler_info()["workers"]) == 2
        lines = brume.dask.run(client, manifest, tmp_path / "dask", seed=4, threads=1, progress=False)
    assert [l["status"] for l in lines] == ["ok"] * 3
    assert [l["key"] for l in lines] == [r["key"] for r in rows]
    for r in rows:
        stem = r["key"][:-4]
        a = brume.read_image(tmp_path / "cli" / (stem + ".png"), transfer="linear").rgb
        b = brume.read_image(tmp_path / "dask" / (stem + ".png"), transfer="linear").rgb
        assert a.shape == b.shape and np.array_equal(a.view(np.uint32), b.view(np.uint32)), stem
        assert _records_equal(tmp_path / "cli", tmp_path / "dask", stem + ".json"), stem
    cli = [json.loads(l) for l in (tmp_path / "cli" / "results.jsonl").read_text().splitlines()]
    dsk = [json.loads(l) for l in (tmp_path / "dask" / "results.jsonl").read_text().splitlines()]
    assert [c["parameters"] for c in cli] == [d["parameters"] for d in dsk]
