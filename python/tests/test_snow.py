"""brume.lidar.snow and brume.snow (issue #58): the scan and the image the CLI writes, bit for bit;
the Snow transform."""
import json

import numpy as np
import pytest

import brume
from conftest import run_cli, scan


def test_lidar_snow_equals_cli_bit_for_bit(tmp_path):
    """The points and labels of `brume lidar snow` on the same scan; rate 0 gives the scan back;
    the errors name the keyword."""
    pts = scan()
    pts[::5, 3] = 0.0  # reflectance-0 points, as KITTI's 8.5 %
    pts.tofile(tmp_path / "in.bin")
    run_cli("lidar", "snow", "--points", tmp_path / "in.bin", "--rate", 2, "--seed", 4,
            "--distribution", "sekhon-srivastava", "--out", tmp_path / "out.bin", "--labels", tmp_path / "labels.u8")
    r = brume.lidar.snow(pts, rate=2.0, seed=4, distribution="sekhon-srivastava")
    assert np.array_equal(r.points, np.fromfile(tmp_path / "out.bin", dtype=np.float32).reshape(-1, 4))
    assert np.array_equal(r.labels, np.fromfile(tmp_path / "labels.u8", dtype=np.uint8))
    counts = np.bincount(r.labels, minlength=3)
    assert counts[1] == r.record["snow"]["moved_to_flakes"] > 0
    assert r.record["command"] == "lidar snow"
    # The last return of frame 3, as the command line's --return-mode last --frame 3.
    run_cli("lidar", "snow", "--points", tmp_path / "in.bin", "--rate", 2, "--seed", 4, "--return-mode", "last",
            "--frame", 3, "--out", tmp_path / "last.bin")
    last = brume.lidar.snow(pts, rate=2.0, seed=4, return_mode="last", frame=3)
    assert np.array_equal(last.points, np.fromfile(tmp_path / "last.bin", dtype=np.float32).reshape(-1, 4))
    assert last.record["snow"]["return_mode"] == "last" and last.record["snow"]["frame"] == 3
    with pytest.raises(ValueError, match="return_mode="):
        brume.lidar.snow(pts, rate=1.0, return_mode="first")
    assert np.array_equal(brume.lidar.snow(pts, rate=0.0).points, pts)
    with pytest.raises(ValueError, match="rate"):
        brume.lidar.snow(pts)
    with pytest.raises(ValueError, match="flake_density=2"):
        brume.lidar.snow(pts, rate=1.0, flake_density=2.0)


def same(a, b):
    assert a.shape == b.shape and a.dtype == b.dtype
    assert np.array_equal(a, b, equal_nan=True), f"max |diff| {np.nanmax(np.abs(a - b))}"


def test_snow_equals_cli(demo, tmp_path):
    """brume.snow on arrays against `brume snow` on the demo scene's files: the image, the
    transmission and the scan of lidar= (brume.lidar.snow's), bit for bit; its job repeats it."""
    import brume.transforms as T
    d = demo["dir"]
    pts = scan(n=2000)
    pts.tofile(tmp_path / "in.bin")
    run_cli("snow", "--image", d / "clean.png", "--range", d / "range.exr", "--fov-y", 55, "--rate", 2,
            "--snow-seed", 3, "--wind", "0,2,0", "--visibility", 400, "--lidar", tmp_path / "in.bin",
            "--lidar-out", tmp_path / "out.bin", "--out", tmp_path / "o.exr", "--bits", "float",
            "--transmission", tmp_path / "t.exr")
    r = brume.snow(demo["rgb"], demo["range"], fov_y=55, rate=2, snow_seed=3, wind="0,2,0", visibility=400, lidar=pts)
    same(r.rgb, brume.read_image(tmp_path / "o.exr").rgb)
    same(r.transmission, brume.depth.convert(range=tmp_path / "t.exr").range)
    same(r.lidar, np.fromfile(tmp_path / "out.bin", np.float32).reshape(-1, 4))
    alone = brume.lidar.snow(pts, rate=2, seed=3)
    same(r.lidar, alone.points)
    assert r.record["snow"]["flakes_drawn"] > 0 and r.record["job"]["lidar"] == {}
    again = brume.snow(demo["rgb"], demo["range"], job=json.loads(json.dumps(r.record["job"])), lidar=pts)
    same(again.rgb, r.rgb)
    # the Snow transform: a rate and a seed per key, replayed
    t = T.Snow(seed=5, fov_y=55)
    out = t(image=demo["rgb"], depth=demo["range"], key="demo/0")
    v = out["params"]["values"]
    assert set(v) == {"rate", "snow-seed"} and 0.2 <= v["rate"] < 5
    same(out["image"], brume.snow(demo["rgb"], demo["range"], fov_y=55, rate=v["rate"], snow_seed=v["snow-seed"]).rgb)
    same(T.Snow(seed=9, fov_y=55).replay(json.loads(json.dumps(out["params"])))(image=demo["rgb"],
                                                                                 depth=demo["range"])["image"],
         out["image"])
    with pytest.raises(ValueError, match="rate"):
        brume.snow(demo["rgb"], demo["range"], fov_y=55)


def test_snow_frames_equal_cli(demo, tmp_path):
    """frame= is --frame: frame 3 of a sequence as `brume snow` draws it, bit for bit, and the Snow
    transform passes it on; lidar= at frame 1 is brume.lidar.snow's frame=1 (fresh flakes per beam)."""
    import brume.transforms as T
    d = demo["dir"]
    run_cli("snow", "--image", d / "clean.png", "--range", d / "range.exr", "--fov-y", 55, "--rate", 2,
            "--snow-seed", 3, "--wind", "0,2,0", "--ego-speed", 5, "--frame", 3,
            "--out", tmp_path / "o.exr", "--bits", "float")
    kw = dict(fov_y=55, rate=2, snow_seed=3, wind="0,2,0", ego_speed=5)
    r = brume.snow(demo["rgb"], demo["range"], frame=3, **kw)
    same(r.rgb, brume.read_image(tmp_path / "o.exr").rgb)
    assert r.record["snow"]["frame"] == 3
    out = T.Snow(seed=5, frame=3, **kw)(image=demo["rgb"], depth=demo["range"], key="k")
    same(out["image"], r.rgb)
    pts = scan(n=50)
    with_scan = brume.snow(demo["rgb"], demo["range"], frame=1, lidar=pts, **kw)
    same(with_scan.lidar, brume.lidar.snow(pts, rate=2, seed=3, frame=1).points)
    # kitti_calib= places the camera of poses= (as --kitti-calib), and alone changes nothing: refused
    from test_rain import KITTI_CALIB
    calib, poses = tmp_path / "calib.txt", tmp_path / "poses.txt"
    calib.write_text(KITTI_CALIB)
    poses.write_text("".join(f"1 0 0 0 0 1 0 0 0 0 1 {0.5 * k} \n" for k in range(3)))
    run_cli("snow", "--image", d / "clean.png", "--range", d / "range.exr", "--fov-y", 55, "--rate", 2,
            "--snow-seed", 3, "--kitti-calib", calib, "--poses", poses, "--frame", 2,
            "--out", tmp_path / "p.exr", "--bits", "float")
    kp = dict(fov_y=55, rate=2, snow_seed=3)
    same(brume.snow(demo["rgb"], demo["range"], kitti_calib=str(calib), poses=str(poses), frame=2, **kp).rgb,
         brume.read_image(tmp_path / "p.exr").rgb)
    with pytest.raises(ValueError, match="kitti_calib="):
        brume.snow(demo["rgb"], demo["range"], kitti_calib=str(calib), **kp)


def test_snow_transform_lidar_target(demo):
    """lidar_target="points": the frame's scan through the same draw (brume.lidar.snow at the drawn
    rate and snow-seed), the image as drawn without a scan, both replayed; refusals name the keyword."""
    import brume.transforms as T
    rgb, rng = demo["rgb"], demo["range"]
    pts = scan(n=2000)
    t = T.Snow(seed=3, fov_y=55, lidar_target="points")
    out = t(image=rgb, depth=rng, points=pts, key="f")
    v = out["params"]["values"]
    same(out["points"], brume.lidar.snow(pts, rate=v["rate"], seed=v["snow-seed"]).points)
    same(out["image"], T.Snow(seed=3, fov_y=55)(image=rgb, depth=rng, key="f")["image"])
    params = json.loads(json.dumps(out["params"]))
    again = t.replay(params)(image=rgb, depth=rng, points=pts)
    same(again["image"], out["image"])
    same(again["points"], out["points"])
    with pytest.raises(ValueError, match="lidar_target"):
        T.Snow(seed=3, fov_y=55).replay(params)
    with pytest.raises(ValueError, match="points"):
        t(image=rgb, depth=rng, key="f")
