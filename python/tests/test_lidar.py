"""brume.lidar.fog: an (N, 4) float32 scan read in place, the same points as
`brume lidar fog` on the same scan (bit for bit), its errors."""
import numpy as np
import pytest

import brume
from brume import _brume
from conftest import run_cli, scan


def test_lidar_fog_equals_cli_and_reads_in_place(tmp_path):
    pts = scan()
    pts.tofile(tmp_path / "in.bin")
    run_cli("lidar", "fog", "--points", tmp_path / "in.bin", "--visibility", 40, "--seed", 5,
            "--out", tmp_path / "out.bin")
    r = brume.lidar.fog(pts, visibility=40.0, seed=5)
    assert r.points.shape == pts.shape and r.points.dtype == np.float32
    assert np.array_equal(r.points, np.fromfile(tmp_path / "out.bin", dtype=np.float32).reshape(-1, 4))
    assert r.record["inputs"]["points"]["copied"] is False
    assert r.record["lidar"]["alpha_per_m"] == 3.912 / 40
    assert r.record["lidar"]["soft_points"] > 0
    assert r.record["command"] == "lidar fog"
    # No fog: the same points, bit for bit.
    assert np.array_equal(brume.lidar.fog(pts, alpha=0.0).points, pts)
    assert brume.lidar.fog is _brume.lidar_fog


def test_lidar_fog_errors():
    pts = scan(50)
    with pytest.raises(ValueError, match=r"\(N, 4\)"):
        brume.lidar.fog(pts[:, :3], alpha=0.1)
    with pytest.raises(ValueError, match="alpha"):
        brume.lidar.fog(pts, alpha=-1.0)
    in_0_255 = pts.copy()
    in_0_255[:, 3] *= 255  # intensities already in [0, 255] (the points stay within 10 km: issue #51)
    with pytest.raises(ValueError, match="intensity_scale=1"):
        brume.lidar.fog(in_0_255, alpha=0.1)
    with pytest.raises(ValueError, match="visibility"):
        brume.lidar.fog(pts)


def test_camera_record_with_a_scan(demo, tmp_path):
    """`brume haze --lidar`: the record's alpha is the camera's extinction;
    brume.lidar.fog with that alpha gives the same scan; haze's job= of such a
    record needs the scan as lidar= (refused without it; with it, the same
    scan), of a record without one it still replays."""
    pts = scan(3000, seed=7)
    pts.tofile(tmp_path / "in.bin")
    d = demo["dir"]
    run_cli("haze", "--image", d / "clean.png", "--range", d / "range.exr", "--visibility", 90,
            "--lidar", tmp_path / "in.bin", "--lidar-out", tmp_path / "s.bin", "--lidar-seed", 3,
            "--out", tmp_path / "o.png", "--record", tmp_path / "o.json")
    import json
    rec = json.load(open(tmp_path / "o.json"))
    alpha = rec["lidar"]["alpha_per_m"]
    assert alpha == rec["haze"]["derived"]["extinction_per_m"] == 3.912 / 90
    r = brume.lidar.fog(pts, alpha=alpha, seed=3)
    assert np.array_equal(r.points, np.fromfile(tmp_path / "s.bin", dtype=np.float32).reshape(-1, 4))
    with pytest.raises(ValueError, match="no lidar= scan"):
        brume.haze(demo["rgb"], demo["range"], job=rec["job"])
    assert np.array_equal(brume.haze(demo["rgb"], demo["range"], job=rec["job"], lidar=pts).lidar, r.points)
    plain = brume.haze(demo["rgb"], demo["range"], visibility=90.0)
    assert "lidar" not in plain.record
    again = brume.haze(demo["rgb"], demo["range"], job=plain.record["job"])
    assert np.array_equal(again.rgb, plain.rgb)


def test_lidar_fog_layered_keywords(tmp_path):
    """The height-layered fog's flags are keywords (from the same table):
    the same scan as `brume lidar fog --profile ...`, bit for bit."""
    pts = scan()
    pts.tofile(tmp_path / "in.bin")
    run_cli("lidar", "fog", "--points", tmp_path / "in.bin", "--profile", "exponential", "--density", 0.08,
            "--falloff", 0.2, "--sensor-height", 1.7, "--seed", 3, "--out", tmp_path / "out.bin")
    r = brume.lidar.fog(pts, profile="exponential", density=0.08, falloff=0.2, sensor_height=1.7, seed=3)
    assert np.array_equal(r.points, np.fromfile(tmp_path / "out.bin", dtype=np.float32).reshape(-1, 4))
    assert r.record["lidar"]["profile"] == "exponential"
    assert r.record["lidar"]["alpha_per_m"] is None
    assert r.record["lidar"]["origin_height_m"] == 1.7
    with pytest.raises(ValueError, match="profile='exponential' and alpha"):
        brume.lidar.fog(pts, profile="exponential", sensor_height=1.7, alpha=0.1)
    with pytest.raises(ValueError, match="sensor_height"):
        brume.lidar.fog(pts, profile="exponential")


def test_lidar_rain_equals_cli_bit_for_bit(tmp_path):
    """brume.lidar.rain: the points and labels `brume lidar rain` writes on the
    same scan, bit for bit; rate 0 gives the scan back; its errors name the keyword."""
    pts = scan()
    pts[::5, 3] = 0.0  # reflectance-0 points, as KITTI's 8.5 %
    pts.tofile(tmp_path / "in.bin")
    run_cli("lidar", "rain", "--points", tmp_path / "in.bin", "--rate", 100, "--seed", 4,
            "--out", tmp_path / "out.bin", "--labels", tmp_path / "labels.u8")
    r = brume.lidar.rain(pts, rate=100.0, seed=4)
    assert r.points.dtype == np.float32 and r.labels.dtype == np.uint8 and r.labels.shape == (len(pts),)
    assert np.array_equal(r.points, np.fromfile(tmp_path / "out.bin", dtype=np.float32).reshape(-1, 4))
    assert np.array_equal(r.labels, np.fromfile(tmp_path / "labels.u8", dtype=np.uint8))
    counts = np.bincount(r.labels, minlength=3)
    assert counts[1] == r.record["rain"]["moved_to_drops"] > 0
    assert counts[2] == r.record["rain"]["lost"] and len(r.points) == counts[0] + counts[1]
    assert r.record["command"] == "lidar rain"
    assert r.record["inputs"]["points"]["copied"] is False
    clear = brume.lidar.rain(pts, rate=0.0)
    assert np.array_equal(clear.points, pts) and not clear.labels.any()
    with pytest.raises(ValueError, match="rate"):
        brume.lidar.rain(pts)
    with pytest.raises(ValueError, match="rate"):
        brume.lidar.rain(pts, rate=-1.0)
    with pytest.raises(ValueError, match=r"\(N, 4\)"):
        brume.lidar.rain(pts[:, :3], rate=5.0)
