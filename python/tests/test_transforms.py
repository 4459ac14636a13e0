"""brume.transforms and the module in forked workers (issue #42): fork safety,
the albumentations call protocol, types, determinism, replay against the CLI,
clips, bad arguments."""
import math
import multiprocessing

import numpy as np
import pytest

import brume

# A forked child that hangs fails its test after this long instead of hanging
# ctest: the effects below take milliseconds (64 x 48 pixels).
FORK_TIMEOUT_S = 60


def _scene(h=48, w=64, seed=0):
    g = np.random.default_rng(seed)
    rgb = g.random((h, w, 3), dtype=np.float32)
    yy, xx = np.mgrid[0:h, 0:w]
    rng = (20.0 + 3.0 * xx + 0.5 * yy).astype(np.float32)
    return rgb, rng


# ---- fork safety (item 5) -------------------------------------------------------------------
def _child_haze(threads):
    rgb, rng = _scene()
    kw = {} if threads is None else {"threads": threads}
    return brume._brume._in_forked_child(), brume.haze(rgb, rng, visibility=300, **kw).rgb


def test_forked_pool_runs_effects_after_the_parent_ran_one():
    """The parent opens libgomp's pool (threads=2), then forks a Pool whose
    workers run effects: with the default threads (one thread in a forked
    child) and with threads=2 asked for (a thread of its own, fresh pool).
    Without the fork handling the workers wait forever on the parent's pool;
    the timeout turns that into a failure. Results equal the parent's bits
    (results do not depend on threads)."""
    rgb, rng = _scene()
    parent = brume.haze(rgb, rng, visibility=300, threads=2).rgb
    assert not brume._brume._in_forked_child()
    with multiprocessing.get_context("fork").Pool(2) as pool:
        got = pool.map_async(_child_haze, [None, 2, None, 2, 1]).get(timeout=FORK_TIMEOUT_S)
    for forked, child in got:
        assert forked
        np.testing.assert_array_equal(child, parent)


# ---- brume.transforms ---------------------------------------------------------------------------
import hashlib  # noqa: E402
import json  # noqa: E402
import random  # noqa: E402

from brume import transforms as T  # noqa: E402

from conftest import assert_gil_released, run_cli  # noqa: E402


def _torch():
    try:
        import torch
    except ImportError:
        pytest.skip("torch is absent (apt python3-torch python3-torchvision; scripts/install-deps.sh)")
    return torch


def test_classes_come_from_the_list_of_commands():
    """One class per sampled effect on (rgb, range) arrays and per chain of
    them: the names the issue asks for, none written per effect."""
    sampled = {c["name"] for c in brume._brume._commands() if c["sampling"] and c["arrays"] == ["rgb", "range"]}
    assert sampled >= {"haze", "fog", "aerial", "dof"}
    for name in ("Haze", "Fog", "Aerial", "DepthOfField", "HazeThenDof"):
        assert issubclass(getattr(T, name), T.Transform)
    assert T.HazeThenDof._commands == ("haze", "dof")


def test_protocol_numpy_types_shapes_and_targets():
    """t(image=, depth=, key=, **targets) -> dict: the image in the dtype,
    shape and range it came in, the depth and other targets untouched (the
    same objects), params JSON-serialisable with values, seed, key, record."""
    rgb, rng = _scene()
    t = T.Haze(visibility=(150, 600), albedo=0.9, seed=7)
    mask = np.zeros((48, 64), np.uint8)
    for img in (rgb, (rgb * 255).astype(np.uint8), (rgb * 65535).astype(np.uint16)):
        out = t(image=img, depth=rng, key="a", mask=mask)
        assert set(out) == {"image", "depth", "mask", "params"}
        assert out["image"].dtype == img.dtype and out["image"].shape == img.shape
        assert out["depth"] is rng and out["mask"] is mask
        p = out["params"]
        assert json.loads(json.dumps(p)) == p
        assert p["seed"] == 7 and p["key"] == "a" and p["applied"]
        assert 150 <= p["values"]["visibility"] < 600 and p["values"]["albedo"] == 0.9
        assert p["record"]["tool"] == "brume" and p["record"]["job"]["haze"]["visibility"] == p["values"]["visibility"]
    # float with transfer="srgb": decoded, run, encoded back, in [0, 1]
    out = T.Haze(visibility=300, transfer="srgb")(image=rgb, depth=rng, key="a")["image"]
    assert out.dtype == np.float32 and 0.0 <= out.min() and out.max() <= 1.0
    # uint8 is sRGB by default: the same as the library on the same uint8 with transfer="srgb", encoded back
    u8 = (rgb * 255).astype(np.uint8)
    out = T.Haze(visibility=300)(image=u8, depth=rng, key="a")
    lib = brume.haze(u8, rng, transfer="srgb", **out["params"]["values"]).rgb.astype(np.float64)
    enc = np.where(lib <= 0.0031308, lib * 12.92, 1.055 * np.clip(lib, 0, 1) ** (1 / 2.4) - 0.055)
    # the encode runs in float32 in the transform: a rounding tie may land one code away
    assert np.abs(out["image"].astype(int) - np.floor(np.clip(enc, 0, 1) * 255 + 0.5)).max() <= 1


def test_float32_hwc_is_read_in_place_and_the_effect_matches_the_function():
    rgb, rng = _scene()
    out = T.Haze(visibility=300, lambda_=4)(image=rgb, depth=rng, key="k")
    seen = brume._brume._debug_last_inputs()["rgb"]
    assert not seen["copied"] and seen["address"] == rgb.__array_interface__["data"][0]
    np.testing.assert_array_equal(out["image"], brume.haze(rgb, rng, visibility=300, **{"lambda": 4},
                                                           albedo=out["params"]["values"]["albedo"]).rgb)


def test_compose_like_list():
    """Inside a plain list applied in turn (what Compose does), with a
    target the transforms pass through."""
    rgb, rng = _scene()
    pipeline = [T.Haze(visibility=400, seed=1), T.DepthOfField(f_number=2.8, focus_distance=40, seed=2)]
    data = {"image": rgb, "depth": rng, "label": 3}
    for t in pipeline:
        data = t(**data, key="frame0")
    assert data["label"] == 3 and data["image"].shape == rgb.shape
    assert data["params"]["values"]["f-number"] == 2.8


def _unit(seed, key, name):  # the documented hash of brume/sample.hpp, independent of the module
    msg = b"brume-sample-v1\0" + str(seed).encode() + b"\0" + key.encode() + b"\0" + name.encode()
    return (int.from_bytes(hashlib.sha256(msg).digest()[:8], "big") >> 11) / 2 ** 53


def test_draws_are_the_documented_function_of_seed_and_key():
    """A draw depends on (seed, key) only: the value is the inverse CDF at the
    documented hash (so the same across runs, processes and workers), and no
    global RNG (random, numpy's legacy one) is touched. Without key=, keys are
    call:<worker>:<counter>."""
    rgb, rng = _scene()
    state_py, state_np = random.getstate(), np.random.get_state()
    t = T.Haze(visibility=T.loguniform(100, 1000), seed=11)
    v = t(image=rgb, depth=rng, key="Art/view1.png")["params"]["values"]["visibility"]
    u = _unit(11, "Art/view1.png", "visibility")
    assert v == pytest.approx(math.exp(math.log(100) + u * (math.log(1000) - math.log(100))), rel=1e-12)
    assert random.getstate() == state_py
    assert all(np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b
               for a, b in zip(np.random.get_state(), state_np))
    keys = [t(image=rgb, depth=rng)["params"]["key"] for _ in range(2)]
    assert keys == ["call:0:0", "call:0:1"]
    # another instance, the same key: the same bits
    a = T.Haze(visibility=T.loguniform(100, 1000), seed=11)(image=rgb, depth=rng, key="x")["image"]
    b = T.Haze(visibility=T.loguniform(100, 1000), seed=11)(image=rgb, depth=rng, key="x")["image"]
    np.testing.assert_array_equal(a, b)


def test_p_zero_is_the_identity_and_p_draws_are_keyed():
    rgb, rng = _scene()
    out = T.Haze(p=0.0)(image=rgb, depth=rng, key="a")
    assert out["image"] is rgb and out["params"]["applied"] is False and out["params"]["record"] is None
    t = T.Haze(p=0.5, visibility=300, seed=5)
    applied = [t(image=rgb, depth=rng, key=str(i))["params"]["applied"] for i in range(40)]
    assert applied == [_unit(5, str(i), "p") < 0.5 for i in range(40)]
    assert 0 < sum(applied) < 40


def _cli_run_of(record, rgb, rng, tmp_path, template_args=()):
    """The CLI's `brume run` of a transform's record on the same pixels:
    the pixels as float PFM files, a CLI record of those files with the
    Python record's job blocks, run, its output read back."""
    brume.write_image(tmp_path / "rgb.pfm", rgb, bits="float")
    brume.write_image(tmp_path / "range.pfm", rng, bits="float", data=True)
    command = record["command"]
    run_cli(command, "--image", tmp_path / "rgb.pfm", "--range", tmp_path / "range.pfm", "--out",
            tmp_path / "o.pfm", "--bits", "float", "--record", tmp_path / "template.json", *template_args)
    cli = json.loads((tmp_path / "template.json").read_text())
    for block, values in record["job"].items():  # (dof's "depth" block: intrinsics over the template's files)
        cli["job"].setdefault(block, {}).update(values)
    (tmp_path / "rec.json").write_text(json.dumps(cli))
    run_cli("run", tmp_path / "rec.json", "--out-dir", tmp_path / "again")
    return brume.read_image(tmp_path / "again" / "o.pfm").rgb


@pytest.mark.parametrize("cls, kw, template", [(T.Haze, dict(visibility=(150, 600)), ()),
                                               (T.DepthOfField, dict(focus_distance=(5, 60)),
                                                ("--focus-distance", 10, "--f-number", 2, "--focal-length", 50,
                                                 "--sensor-width", 36)),
                                               (T.Aerial, dict(), ())])
def test_replay_is_bit_for_bit_and_equals_the_cli_run_of_the_record(cls, kw, template, tmp_path):
    """replay(params) repeats a sample bit for bit, after a JSON round trip
    and from another object of the class; `brume run` of the record (its job
    blocks in a CLI record of the same pixels) writes the same bits."""
    rgb, rng = _scene()
    rng = rng.copy()
    rng[:4, 10:30] = 0.0  # unknown: prepared, as on the command line
    t = cls(seed=3, **kw)
    out = t(image=rgb, depth=rng, key="frame/1")
    params = json.loads(json.dumps(out["params"]))
    again = t.replay(params)(image=rgb, depth=rng)
    np.testing.assert_array_equal(again["image"], out["image"])
    # another transform object of the class replays it too (the record carries everything)
    np.testing.assert_array_equal(cls().replay(params)(image=rgb, depth=rng)["image"], out["image"])
    unknown = rng.copy()
    unknown[unknown == 0] = np.nan
    np.testing.assert_array_equal(_cli_run_of(params["record"], rgb, unknown, tmp_path, template), out["image"])


def test_invalid_depth_is_unknown_and_units():
    """0, NaN, inf and negative depth are unknown (NaN to the library, then
    prepared); depth_unit='mm' scales integer millimetres."""
    rgb, rng = _scene()
    bad = rng.copy()
    bad[0, :5] = [0, np.nan, np.inf, -1, -np.inf]
    nan = rng.copy()
    nan[0, :5] = np.nan
    t = T.Haze(visibility=300)
    np.testing.assert_array_equal(t(image=rgb, depth=bad, key="k")["image"],
                                  t(image=rgb, depth=nan, key="k")["image"])
    mm = np.round(rng * 1000).astype(np.uint16)
    metres = (mm.astype(np.float64) * 0.001).astype(np.float32)
    np.testing.assert_array_equal(T.Haze(visibility=300, depth_unit="mm")(image=rgb, depth=mm, key="k")["image"],
                                  t(image=rgb, depth=metres, key="k")["image"])
    # z along the optical axis -> range along the ray: range = z sqrt(1 + u^2 + v^2), in double
    h, w = rng.shape
    z = rng.astype(np.float64)
    yy, xx = np.mgrid[0:h, 0:w]
    ray = (z * np.sqrt(1 + ((xx - 31.5) / 50.0) ** 2 + ((yy - 23.5) / 50.0) ** 2)).astype(np.float32)
    np.testing.assert_array_equal(T.Haze(visibility=300, depth_kind="z", fx=50.0)(image=rgb, depth=rng,
                                                                                     key="k")["image"],
                                  t(image=rgb, depth=ray, key="k")["image"])
    # disparity (px) and inverse depth (1/mm) of the same z: z = fx B / d, z = 0.001 / d metres. The double
    # round trip may move a range by one float32 ulp (~4e-6 m at 60 m), which moves an output value by far
    # less than 1e-5; a wrong formula (a missing factor of fx B or 1000) moves it by tenths.
    for kw, d in ((dict(depth_kind="disparity", fx=50.0, baseline=0.2), 50.0 * 0.2 / z),
                  (dict(depth_kind="inverse", depth_unit="mm", fx=50.0), 0.001 / z)):
        np.testing.assert_allclose(T.Haze(visibility=300, **kw)(image=rgb, depth=d, key="k")["image"],
                                   t(image=rgb, depth=ray, key="k")["image"], rtol=0, atol=1e-5)


def test_clips_share_one_draw_and_per_frame_draws_each():
    rgb, rng = _scene()
    frames = [rgb, rgb[::-1].copy(), rgb[:, ::-1].copy()]
    depths = [rng] * 3
    out = T.Haze(visibility=(100, 900), seed=2)(images=frames, depths=depths, key="clip7")
    assert set(out) == {"images", "depths", "params"} and len(out["images"]) == 3
    jobs = [r["job"] for r in out["params"]["records"]]
    assert all(j == jobs[0] for j in jobs)
    for f, o in zip(frames, out["images"]):
        np.testing.assert_array_equal(o, brume.haze(f, rng, job=jobs[0]).rgb)
    per = T.Haze(visibility=(100, 900), seed=2, per_frame=True)(images=frames, depths=depths, key="clip7")
    vis = [f["values"]["visibility"] for f in per["params"]["frames"]]
    assert len(set(vis)) == 3


def test_bad_arguments_name_the_argument():
    rgb, rng = _scene()
    with pytest.raises(ValueError, match="visibility"):
        T.Haze(visibility=(-5, 100))  # outside the table's range (0, inf)
    with pytest.raises(ValueError, match="albedo"):
        T.Haze(albedo=(0.5, 1.5))
    with pytest.raises(ValueError, match="depth"):
        T.Haze()(image=rgb, depth=rng[:10], key="k")
    with pytest.raises(ValueError, match="depth_unit"):
        T.Haze()(image=rgb, depth=rng.astype(np.uint8), key="k")
    with pytest.raises(ValueError, match="image"):
        T.Haze()(image=rgb[..., 0], depth=rng, key="k")
    with pytest.raises(ValueError, match="p="):
        T.Haze(p=2)
    with pytest.raises(TypeError, match="visibilty"):
        T.Haze(visibilty=300)
    with pytest.raises(ValueError, match="fx"):
        T.Haze(depth_kind="z")


def _pool_transform(i):
    rgb, rng = _scene()
    return T.Haze(visibility=(150, 600), seed=4)(image=rgb, depth=rng, key=str(i))["image"]


def test_transform_in_a_forked_pool_after_the_parent_ran_one():
    rgb, rng = _scene()
    parent = [T.Haze(visibility=(150, 600), seed=4)(image=rgb, depth=rng, key=str(i))["image"] for i in range(4)]
    with multiprocessing.get_context("fork").Pool(2) as pool:
        got = pool.map_async(_pool_transform, range(4)).get(timeout=FORK_TIMEOUT_S)
    for a, b in zip(got, parent):
        np.testing.assert_array_equal(a, b)


# ---- torch ----------------------------------------------------------------------------------------
def test_torch_tensors_come_back_as_they_came():
    torch = _torch()
    rgb, rng = _scene()
    t = T.Haze(visibility=300)
    f = torch.from_numpy(rgb.transpose(2, 0, 1).copy())
    out = t(image=f, depth=torch.from_numpy(rng), key="k")["image"]
    assert isinstance(out, torch.Tensor) and out.dtype == torch.float32 and tuple(out.shape) == (3, 48, 64)
    assert float(out.min()) >= 0.0 and float(out.max()) <= 1.0
    np.testing.assert_array_equal(out.numpy().transpose(1, 2, 0),
                                  np.clip(t(image=rgb, depth=rng, key="k")["image"], 0, 1))
    u8 = torch.from_numpy((rgb * 255).astype(np.uint8).transpose(2, 0, 1).copy())
    out = t(image=u8, depth=rng, key="k")["image"]
    assert out.dtype == torch.uint8 and tuple(out.shape) == (3, 48, 64)


class _Frames:
    """A torch Dataset of synthetic frames with a Haze transform keyed by index."""

    def __init__(self):
        self.t = T.Haze(visibility=(150, 600), lambda_=(0, 6), seed=9)

    def __len__(self):
        return 6

    def __getitem__(self, i):
        rgb, rng = _scene(seed=i)
        return self.t(image=rgb, depth=rng, key=f"frame{i}")["image"]


def test_dataloader_workers_0_and_2_give_the_same_samples():
    torch = _torch()
    from torch.utils.data import DataLoader

    def run(workers):
        dl = DataLoader(_Frames(), batch_size=2, num_workers=workers,
                        multiprocessing_context="fork" if workers else None)
        return torch.cat([b for b in dl]).numpy()

    np.testing.assert_array_equal(run(0), run(2))


def test_haze_then_dof_equals_the_cli_chain(tmp_path):
    """HazeThenDof's draw run by `brume haze --dof-...` (the chain: the range
    prepared once, the hazy RGB handed to the DOF stage) gives the same bits;
    its record is one haze+dof record, which replays and which `brume run`
    repeats; a two-stage record of the earlier form still replays."""
    rgb, rng = _scene()
    t = T.HazeThenDof(visibility=(150, 600), dof_focus_distance=(20, 80), dof_f_number=2.8, seed=1)
    out = t(image=rgb, depth=rng, key="k")
    v = out["params"]["values"]
    assert set(v) == {"haze", "dof"} and 20 <= v["dof"]["focus-distance"] < 80
    rec = out["params"]["record"]
    assert rec["command"] == "haze+dof" and {"haze", "dof", "prepare"} <= set(rec["job"])
    dof = rec["job"]["dof"]  # (the chain names its DOF block's values as its flags: dof-f-number)
    assert dof["dof-f-number"] == 2.8 and dof["dof-focus-distance"] == v["dof"]["focus-distance"]
    np.testing.assert_array_equal(t.replay(json.loads(json.dumps(out["params"])))(image=rgb, depth=rng)["image"],
                                  out["image"])
    # the record through the CLI: a haze+dof record of the same pixels as files with the record's job blocks
    brume.write_image(tmp_path / "rgb.pfm", rgb, bits="float")
    brume.write_image(tmp_path / "range.pfm", rng, bits="float", data=True)
    run_cli("haze", "--image", tmp_path / "rgb.pfm", "--range", tmp_path / "range.pfm", "--out", tmp_path / "t.pfm",
            "--bits", "float", "--dof-focus-distance", 10, "--dof-f-number", 2, "--dof-focal-length", 50,
            "--dof-sensor-width", 36, "--record", tmp_path / "template.json")
    cli = json.loads((tmp_path / "template.json").read_text())
    assert cli["command"] == "haze+dof"
    for block, values in rec["job"].items():
        cli["job"].setdefault(block, {}).update(values)
    cli["job"]["output"]["out"] = str(tmp_path / "r.pfm")
    cli["job"]["output"]["record"] = ""
    (tmp_path / "rec.json").write_text(json.dumps(cli))
    run_cli("run", tmp_path / "rec.json")
    np.testing.assert_array_equal(brume.read_image(tmp_path / "r.pfm").rgb, out["image"])
    # params saved before HazeThenDof ran the chain's function: {"stages": [haze's record, dof's]}
    h = brume.haze(rgb, rng, **v["haze"])
    d = brume.dof(h.rgb, rng, **v["dof"])
    old = dict(out["params"], record={"stages": [h.record, d.record]})
    np.testing.assert_array_equal(t.replay(json.loads(json.dumps(old)))(image=rgb, depth=rng)["image"], d.rgb)
    brume.write_image(tmp_path / "rgb.pfm", rgb, bits="float")
    brume.write_image(tmp_path / "range.pfm", rng, bits="float", data=True)
    flags = []
    for stage, prefix in (("haze", ""), ("dof", "dof-")):
        for k, x in v[stage].items():
            flags += [f"--{prefix}{k}", repr(x)]
    run_cli("haze", "--image", tmp_path / "rgb.pfm", "--range", tmp_path / "range.pfm", "--out", tmp_path / "o.pfm",
            "--bits", "float", *flags)
    np.testing.assert_array_equal(brume.read_image(tmp_path / "o.pfm").rgb, out["image"])


def test_gil_is_released_during_the_effect():
    """A counting thread keeps counting while a transform runs (the effect
    runs without the GIL; the transform's own numpy steps are short)."""
    g = np.random.default_rng(3)
    rgb = g.random((700, 1000, 3), dtype=np.float32)
    rng = (10 + 500 * g.random((700, 1000))).astype(np.float32)
    t = T.Haze(visibility=200, lambda_=8, threads=1)
    assert_gil_released(lambda: t(image=rgb, depth=rng, key="k"), "transform")


def test_transforms_pickle():
    """Spawned workers (and DataLoader's spawn context) receive the transform
    pickled: the copy draws and runs the same."""
    import pickle
    rgb, rng = _scene()
    t = T.HazeThenDof(visibility=(100, 200), dof_f_number=2.8, seed=6)
    u = pickle.loads(pickle.dumps(t))
    assert type(u) is T.HazeThenDof
    np.testing.assert_array_equal(u(image=rgb, depth=rng, key="a")["image"], t(image=rgb, depth=rng, key="a")["image"])


# ---- LidarFog: the LiDAR effect as a transform on a scan ----------------------------------------------
def _scan(n=3000, seed=3):
    g = np.random.default_rng(seed)
    d = g.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.hstack([d * g.uniform(1.5, 80.0, size=(n, 1)), g.uniform(0, 1, size=(n, 1))]).astype(np.float32)


def test_lidar_fog_transform_protocol_draws_and_types():
    """The class comes from the list (the command's sampling and its (N, 4)
    array form); points in, points out in the same type and shape, other
    targets untouched; draws are a function of (seed, key), the noise seed
    included (two keys, two noise patterns); p=0 is the identity."""
    assert issubclass(T.LidarFog, T.PointsTransform)
    pts = _scan()
    t = T.LidarFog(visibility=(30, 60), seed=9)
    out = t(points=pts, key="0001", labels="kept")
    assert set(out) == {"points", "params", "labels"} and out["labels"] == "kept"
    assert out["points"].shape == pts.shape and out["points"].dtype == np.float32
    v = out["params"]["values"]
    assert 30 <= v["visibility"] < 60 and isinstance(v["seed"], int)
    assert out["params"]["record"]["lidar"]["alpha_per_m"] == 3.912 / v["visibility"]
    assert out["params"]["record"]["lidar"]["soft_points"] > 0
    same = T.LidarFog(visibility=(30, 60), seed=9)(points=pts, key="0001")
    np.testing.assert_array_equal(same["points"], out["points"])
    other = t(points=pts, key="0002")["params"]["values"]
    assert other["seed"] != v["seed"] and other["visibility"] != v["visibility"]
    # the noise seed is the draw's: fixing the visibility, two keys still move the fog returns differently
    a = T.LidarFog(visibility=40, seed=9)(points=pts, key="a")["points"]
    b = T.LidarFog(visibility=40, seed=9)(points=pts, key="b")["points"]
    moved = np.any(a[:, :3] != pts[:, :3], axis=1)
    assert moved.any() and not np.array_equal(a[moved], b[moved])
    off = T.LidarFog(p=0.0)(points=pts, key="k")
    assert off["points"] is pts and off["params"]["applied"] is False
    torch = _torch()
    tt = t(points=torch.from_numpy(pts), key="0001")["points"]
    assert isinstance(tt, torch.Tensor) and tt.dtype == torch.float32
    np.testing.assert_array_equal(tt.numpy(), out["points"])


def test_lidar_fog_transform_replay_equals_the_cli(tmp_path):
    """replay repeats the sample bit for bit (another object, after JSON);
    `brume lidar fog` with the drawn values writes the same bytes."""
    pts = _scan()
    out = T.LidarFog(seed=1, visibility=(30, 50))(points=pts, key="scan/7")
    params = json.loads(json.dumps(out["params"]))
    np.testing.assert_array_equal(T.LidarFog().replay(params)(points=pts)["points"], out["points"])
    pts.tofile(tmp_path / "in.bin")
    v = params["values"]
    run_cli("lidar", "fog", "--points", tmp_path / "in.bin", "--visibility", repr(v["visibility"]), "--seed", v["seed"],
            "--out", tmp_path / "out.bin")
    np.testing.assert_array_equal(np.fromfile(tmp_path / "out.bin", np.float32).reshape(-1, 4), out["points"])


def test_lidar_fog_transform_bad_arguments():
    with pytest.raises(ValueError, match="visibility"):
        T.LidarFog(visibility=(0, 50))
    with pytest.raises(ValueError, match="points"):
        T.LidarFog()(points=_scan()[:, :3], key="k")
    with pytest.raises(ValueError, match="points"):
        T.LidarFog()(key="k")
    with pytest.raises(TypeError, match="unknown argument"):
        T.LidarFog(fov_x=50)
