"""brume.rain (issue #56): the camera's rain on arrays against `brume rain` on
the same files, bit for bit (image, transmission, and the scan of lidar= against
--lidar-out); replays of its job; its errors in Python's words; the Rain
transform (keyed draws, a drop field per key, lidar_target, replay); the
sampling of rain (seed())."""
import json

import numpy as np
import pytest

import brume
import brume.transforms as T
from conftest import run_cli, scan


def read_map(path):
    return brume.depth.convert(range=path).range


def same(a, b):
    assert a.shape == b.shape and a.dtype == b.dtype
    assert np.array_equal(a, b, equal_nan=True), f"max |diff| {np.nanmax(np.abs(a - b))}"


def rain_scan():
    pts = scan(n=500)  # (the scan's rain costs ~0.3 ms a point on random beams: kept small)
    pts[::5, 3] = 0.0  # reflectance-0 points, as KITTI's 8.5 %
    return pts


@pytest.mark.parametrize("extra", [
    {},
    # haze's medium in haze's composite, the thin lens's blur, wind and ego speed, a short exposure
    {"visibility": 400, "focal_length": 35, "sensor_width": 36, "f_number": 2, "focus_distance": 8,
     "wind": "0,3,0", "ego_speed": 10, "exposure_time": 0.008},
])
def test_rain_equals_cli(demo, tmp_path, extra):
    d = demo["dir"]
    pts = rain_scan()
    pts.tofile(tmp_path / "in.bin")
    flags = []
    for k, v in extra.items():
        flags += ["--" + k.replace("_", "-"), v]
    if "focal_length" not in extra:
        flags += ["--fov-y", 55]
    run_cli("rain", "--image", d / "clean.png", "--range", d / "range.exr", "--rate", 25, "--rain-seed", 3,
            *flags, "--lidar", tmp_path / "in.bin", "--lidar-out", tmp_path / "out.bin",
            "--out", tmp_path / "o.exr", "--bits", "float", "--transmission", tmp_path / "t.exr",
            "--record", tmp_path / "o.json")
    kw = dict(extra) if "focal_length" in extra else dict(extra, fov_y=55)
    r = brume.rain(demo["rgb"], demo["range"], rate=25, rain_seed=3, lidar=pts, **kw)
    same(r.rgb, brume.read_image(tmp_path / "o.exr").rgb)
    same(r.transmission, read_map(tmp_path / "t.exr"))
    # the scan: the CLI's --lidar-out, and brume.lidar.rain's with the same rate and seed
    same(r.lidar, np.fromfile(tmp_path / "out.bin", np.float32).reshape(-1, 4))
    alone = brume.lidar.rain(pts, rate=25, seed=3)
    same(r.lidar, alone.points)
    assert np.array_equal(r.lidar_labels, alone.labels) and r.lidar_labels.shape == (len(pts),)
    cli = json.loads((tmp_path / "o.json").read_text())
    assert r.record["rain"]["drops_drawn"] == cli["rain"]["drops_drawn"] > 0
    assert r.record["lidar_rain"]["moved_to_drops"] == cli["lidar_rain"]["moved_to_drops"]
    assert r.record["job"]["rain"]["rain-seed"] == 3 and r.record["job"]["lidar"] == {}
    assert ("haze" in r.record) == ("visibility" in extra)
    # its job repeats it (with the scan as lidar=), also after a JSON round trip
    again = brume.rain(demo["rgb"], demo["range"], job=json.loads(json.dumps(r.record["job"])), lidar=pts)
    same(again.rgb, r.rgb)
    same(again.lidar, r.lidar)
    # without a scan: None for both, the same image
    no_scan = brume.rain(demo["rgb"], demo["range"], rate=25, rain_seed=3, **kw)
    assert no_scan.lidar is None and no_scan.lidar_labels is None and "lidar" not in no_scan.record["job"]
    same(no_scan.rgb, r.rgb)


def test_rain_frames_equal_cli(demo, tmp_path):
    """frame= (and frame_interval=) is --frame: the image and the scan at frame 2 of a sequence as
    `brume rain` draws them, bit for bit; its job repeats it; frame 0 is the call without it."""
    d = demo["dir"]
    pts = rain_scan()
    pts.tofile(tmp_path / "in.bin")
    run_cli("rain", "--image", d / "clean.png", "--range", d / "range.exr", "--fov-y", 55, "--rate", 25,
            "--rain-seed", 3, "--wind", "1,2,0", "--ego-speed", 10, "--frame", 2, "--frame-interval", 0.05,
            "--lidar", tmp_path / "in.bin", "--lidar-out", tmp_path / "out.bin",
            "--out", tmp_path / "o.exr", "--bits", "float", "--record", tmp_path / "o.json")
    kw = dict(fov_y=55, rate=25, rain_seed=3, wind="1,2,0", ego_speed=10)
    r = brume.rain(demo["rgb"], demo["range"], frame=2, frame_interval=0.05, lidar=pts, **kw)
    same(r.rgb, brume.read_image(tmp_path / "o.exr").rgb)
    same(r.lidar, np.fromfile(tmp_path / "out.bin", np.float32).reshape(-1, 4))
    assert r.record["rain"]["frame"] == 2 and r.record["lidar_rain"]["frame"] == 2
    again = brume.rain(demo["rgb"], demo["range"], job=json.loads(json.dumps(r.record["job"])), lidar=pts)
    same(again.rgb, r.rgb)
    zero = brume.rain(demo["rgb"], demo["range"], frame=0, **kw)
    same(zero.rgb, brume.rain(demo["rgb"], demo["range"], **kw).rgb)
    assert not np.array_equal(zero.rgb, r.rgb)
    # poses= needs a KITTI calibration (kitti_calib=)
    with pytest.raises(ValueError, match="poses") as e:
        brume.rain(demo["rgb"], demo["range"], frame=1, poses=str(tmp_path / "poses.txt"), **dict(kw, ego_speed=0))
    assert "--" not in str(e.value) and "kitti_calib=" in str(e.value), str(e.value)


# KITTI object 000000's calibration (training): P2's translation places camera 2, Tr_velo_to_cam and
# R0_rect the scan.
KITTI_CALIB = (
    "P0: 707.0493 0 604.0814 0 0 707.0493 180.5066 0 0 0 1 0\n"
    "P2: 707.0493 0 604.0814 45.75831 0 707.0493 180.5066 -0.3454157 0 0 1 0.004981016\n"
    "R0_rect: 0.9999128 0.01009263 -0.008511932 -0.01012729 0.9999406 -0.004037671 0.008470675 0.004123522 "
    "0.9999556\n"
    "Tr_velo_to_cam: 0.006927964 -0.9999722 -0.002757829 -0.02457729 -0.001162982 0.002749836 -0.9999955 "
    "-0.06127237 0.9999753 0.006931141 -0.001143899 -0.3321029\n")


def test_rain_kitti_calib_equals_cli(demo, tmp_path):
    """kitti_calib= is the depth block's --kitti-calib: lidar= draws its drops in camera 2's frame (the
    image's drops: brume.lidar.rain with kitti_calib, no warning), poses= places the camera at frame K,
    both as `brume rain` does, bit for bit; a calibration that changes nothing is refused."""
    d = demo["dir"]
    calib = tmp_path / "calib.txt"
    calib.write_text(KITTI_CALIB)
    poses = tmp_path / "poses.txt"  # camera 0 moving 1 m forward (its z) a frame
    poses.write_text("".join(f"1 0 0 0 0 1 0 0 0 0 1 {k} \n" for k in range(3)))
    pts = rain_scan()
    pts.tofile(tmp_path / "in.bin")
    run_cli("rain", "--image", d / "clean.png", "--range", d / "range.exr", "--fov-y", 55, "--rate", 25,
            "--rain-seed", 3, "--kitti-calib", calib, "--poses", poses, "--frame", 1,
            "--lidar", tmp_path / "in.bin", "--lidar-out", tmp_path / "out.bin",
            "--out", tmp_path / "o.exr", "--bits", "float", "--record", tmp_path / "o.json")
    kw = dict(fov_y=55, rate=25, rain_seed=3)
    r = brume.rain(demo["rgb"], demo["range"], kitti_calib=str(calib), poses=str(poses), frame=1, lidar=pts, **kw)
    same(r.rgb, brume.read_image(tmp_path / "o.exr").rgb)
    same(r.lidar, np.fromfile(tmp_path / "out.bin", np.float32).reshape(-1, 4))
    assert "warnings" not in r.record["lidar_rain"], r.record["lidar_rain"]
    # the scan in the camera's frame at frame 0: brume.lidar.rain's with the calibration
    r0 = brume.rain(demo["rgb"], demo["range"], kitti_calib=str(calib), lidar=pts, **kw)
    same(r0.lidar, brume.lidar.rain(pts, rate=25, seed=3, kitti_calib=str(calib)).points)
    own = brume.rain(demo["rgb"], demo["range"], lidar=pts, **kw)  # no calibration: the scan's frame, warned
    assert "warnings" in own.record["lidar_rain"] and "warnings" not in r0.record["lidar_rain"]
    again = brume.rain(demo["rgb"], demo["range"], job=json.loads(json.dumps(r.record["job"])), lidar=pts)
    same(again.rgb, r.rgb)
    same(again.lidar, r.lidar)
    for bad in (dict(kitti_calib=str(calib)), dict(kitti_calib=str(calib), lidar=pts, lidar_frame="scan")):
        with pytest.raises(ValueError, match="kitti_calib=") as e:
            brume.rain(demo["rgb"], demo["range"], **bad, **kw)
        assert "--" not in str(e.value), str(e.value)


def test_rain_errors_speak_python(demo):
    rgb, rng = demo["rgb"], demo["range"]
    cases = [
        (dict(fov_y=55), "rate"),                                     # the rate is required
        (dict(fov_y=55, rate=-1), "rate"),
        (dict(fov_y=55, rate=25, f_number=2, focus_distance=8), "focal_length"),       # the thin lens needs the camera in mm
        (dict(fov_y=55, rate=25, drop_min=2, drop_max=1), "drop_max"),
        (dict(fov_y=55, rate=25, wind="0,north,0"), "wind"),
    ]
    for kw, word in cases:
        with pytest.raises(ValueError, match=word) as e:
            brume.rain(rgb, rng, **kw)
        assert "--" not in str(e.value), str(e.value)
    with pytest.raises(ValueError, match=r"\(N, 4\)"):
        brume.rain(rgb, rng, fov_y=55, rate=5, lidar=rain_scan()[:, :3])
    with pytest.raises(TypeError, match="rain_seed"):
        brume.rain(rgb, rng, fov_y=55, rate=5, rain_sed=1)


def test_rain_sampling_draws_a_seed_per_key():
    a = brume.random_params("rain", 7, "frame/0")
    b = brume.random_params("rain", 7, "frame/1")
    assert 1 <= a["rate"] < 100 and isinstance(a["rain-seed"], int) and 0 <= a["rain-seed"] < 2 ** 53
    assert a["rain-seed"] != b["rain-seed"] and a == brume.random_params("rain", 7, "frame/0")
    # seed() is the hash's top 53 bits: the transforms' own scheme (brume-sample-v1)
    assert a["rain-seed"] == int(T._unit(7, "frame/0", "rain-seed") * 2.0 ** 53)
    assert brume.random_params("rain", 7, "frame/0", rain_seed="4")["rain-seed"] == 4
    with pytest.raises(ValueError, match="seed\\(\\) draws a whole number"):
        brume.random_params("rain", 7, "k", rate="seed()")


def test_rain_transform(demo):
    rgb, rng = demo["rgb"], demo["range"]
    t = T.Rain(seed=5, fov_y=55)
    out = t(image=rgb, depth=rng, key="demo/0")
    v = out["params"]["values"]
    assert set(v) == {"rate", "rain-seed"} and 1 <= v["rate"] < 100
    same(out["image"], brume.rain(rgb, rng, fov_y=55, rate=v["rate"], rain_seed=v["rain-seed"]).rgb)
    other = t(image=rgb, depth=rng, key="demo/1")["params"]["values"]
    assert other["rain-seed"] != v["rain-seed"]
    params = json.loads(json.dumps(out["params"]))
    same(T.Rain(seed=99, fov_y=55).replay(params)(image=rgb, depth=rng)["image"], out["image"])
    # a fixed seed draws the same drops for every key; T.seed() (the default) one per key
    fixed = T.Rain(seed=5, fov_y=55, rain_seed=4)
    assert fixed(image=rgb, depth=rng, key="a")["params"]["values"]["rain-seed"] == 4
    assert T.Rain(seed=5, fov_y=55, rain_seed=T.seed())(image=rgb, depth=rng, key="demo/0")["params"]["values"] == v
    # a fixed rate and a range of exposures
    t2 = T.Rain(seed=1, fov_y=55, rate=10, exposure_time=(0.004, 0.03))
    v2 = t2(image=rgb, depth=rng, key="k")["params"]["values"]
    assert v2["rate"] == 10 and 0.004 <= v2["exposure-time"] < 0.03
    # refused when made: a value out of the table's range, in Python's words
    with pytest.raises(ValueError, match="rate"):
        T.Rain(rate=(1, 900), fov_y=55)
    with pytest.raises(ValueError, match="focal_length"):
        T.Rain(f_number=2, focus_distance=8, fov_y=55)


def test_rain_transform_lidar_target(demo):
    rgb, rng = demo["rgb"], demo["range"]
    pts = rain_scan()
    t = T.Rain(seed=3, fov_y=55, lidar_target="points")
    out = t(image=rgb, depth=rng, points=pts, key="f")
    v = out["params"]["values"]
    assert "lidar-seed" not in v  # the scan's drops are the rain's: its seed is rain-seed
    alone = brume.lidar.rain(pts, rate=v["rate"], seed=v["rain-seed"])
    same(out["points"], alone.points)
    # the image is the one drawn without a scan
    same(out["image"], T.Rain(seed=3, fov_y=55)(image=rgb, depth=rng, key="f")["image"])
    assert out["params"]["record"]["lidar_rain"]["points"] == len(pts)
    params = json.loads(json.dumps(out["params"]))
    again = t.replay(params)(image=rgb, depth=rng, points=pts)
    same(again["image"], out["image"])
    same(again["points"], out["points"])
    with pytest.raises(ValueError, match="lidar_target"):
        T.Rain(seed=3, fov_y=55).replay(params)
    with pytest.raises(ValueError, match="points"):
        t(image=rgb, depth=rng, key="f")
    p0 = T.Rain(seed=3, fov_y=55, lidar_target="points", p=0.0)(image=rgb, depth=rng, points=pts, key="f")
    assert p0["image"] is rgb and p0["points"] is pts
