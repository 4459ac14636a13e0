"""The stored records of older schemas (tests/records/README.md) replayed by
brume.rerun on their input files' arrays: a record of an older schema runs
under the rules it ran under (its job completed as `brume run` completes it),
bit for bit the output its own build wrote. The records of the commands
brume.rerun takes (the effects on rgb and a range map); tests/test_records.cpp
replays every stored record with `brume run`."""
import json
from pathlib import Path

import numpy as np
import pytest

import brume
from brume._rerun import _REPLAYABLE

RECORDS = Path(__file__).resolve().parents[2] / "tests" / "records"
EFFECTS = set(_REPLAYABLE)  # the commands brume.rerun takes
# Depth of field's lens, kept in the dof block by records before the camera
# in millimetres joined the depth block (issue #50: ParamSpec::formerly):
# brume.rerun reads it there and records it where it is now.
LENS_MOVED = {"focal-length": "focal-length", "sensor-width": "sensor-width",
              "dof-focal-length": "focal-length", "dof-sensor-width": "sensor-width"}


def stored():
    out = []
    for d in sorted(RECORDS.glob("schema-*")):
        for f in sorted(d.glob("*.json")):
            rec = json.loads(f.read_text())
            if rec.get("command") in EFFECTS and rec["job"]["depth"].get("range"):
                out.append(pytest.param(rec, id=f"{d.name}/{f.stem}"))
    return out


def test_records_of_every_schema_are_replayed():
    # A glob that found nothing would pass every parametrized case vacuously:
    # at least the eight effect records of each of schemas 2, 3 and 4.
    by_schema = {}
    for p in stored():
        by_schema[p.values[0]["schema_version"]] = by_schema.get(p.values[0]["schema_version"], 0) + 1
    assert set(by_schema) >= {2, 3, 4}, by_schema
    assert all(n >= 8 for n in by_schema.values()), by_schema


def bits(a):
    return np.ascontiguousarray(a, dtype=np.float32).tobytes()


@pytest.mark.parametrize("record", stored())
def test_stored_record_repeats_on_arrays(record, monkeypatch):
    monkeypatch.chdir(RECORDS)  # the record's paths are relative to tests/records
    job = record["job"]
    rgb = brume.read_image(job["input"]["image"]).rgb
    rng = brume.read_image(job["depth"]["range"]).rgb[..., 0].copy()
    keywords = {"threads": 2}
    scan = job.get("lidar", {}).get("lidar")
    if scan:
        keywords["lidar"] = np.fromfile(scan, dtype="<f4").reshape(-1, 4)
    again = brume.rerun(record, rgb, rng, **keywords)
    assert bits(again.rgb) == bits(brume.read_image(job["output"]["out"]).rgb)
    if scan:
        assert bits(again.lidar) == Path(job["lidar"]["lidar-out"]).read_bytes()
    # The replay's record: today's schema, the stored job's values, and a
    # schema-2 job's sky at S_max (sky-rule, since schema 3).
    today = brume.blur(np.zeros((2, 2, 3), np.float32), sigma=1.5).record["schema_version"]
    assert again.record["schema_version"] == today >= record["schema_version"]
    for block in ("haze", "fog", "aerial", "dof", "diffusion", "prepare"):
        for name, value in job.get(block, {}).items():
            if block == "dof" and name in LENS_MOVED:  # now the camera's, in the depth block
                assert again.record["job"]["depth"][LENS_MOVED[name]] == value, f"{block}.{name}"
                continue
            assert again.record["job"][block][name] == value, f"{block}.{name}"
        if record["schema_version"] < 3 and block in ("haze", "fog") and block in job:
            assert again.record["job"][block]["sky-rule"] == "s-max"
