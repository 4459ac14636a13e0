"""brume.lidar.snow (issue #58): the scan `brume lidar snow` writes, bit for bit."""
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
    assert np.array_equal(brume.lidar.snow(pts, rate=0.0).points, pts)
    with pytest.raises(ValueError, match="rate"):
        brume.lidar.snow(pts)
    with pytest.raises(ValueError, match="flake_density=2"):
        brume.lidar.snow(pts, rate=1.0, flake_density=2.0)
