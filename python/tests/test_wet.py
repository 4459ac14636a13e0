"""brume.lidar.wet (issue #57): the scan `brume lidar wet` writes, bit for bit."""
import numpy as np
import pytest

import brume
from conftest import run_cli, scan


def ground_scan():
    """The synthetic scan with a third of its points moved onto KITTI's ground (1.73 m below)."""
    pts = scan()
    pts[::3, 2] = -1.73
    return pts


def test_lidar_wet_equals_cli_bit_for_bit(tmp_path):
    """The points and labels of `brume lidar wet` on the same scan; film 0 gives the scan back;
    the errors name the keyword."""
    pts = ground_scan()
    pts.tofile(tmp_path / "in.bin")
    run_cli("lidar", "wet", "--points", tmp_path / "in.bin", "--film", 2, "--noise-floor", 2e-4,
            "--out", tmp_path / "out.bin", "--labels", tmp_path / "labels.u8")
    r = brume.lidar.wet(pts, film=2.0, noise_floor=2e-4)
    assert np.array_equal(r.points, np.fromfile(tmp_path / "out.bin", dtype=np.float32).reshape(-1, 4))
    assert np.array_equal(r.labels, np.fromfile(tmp_path / "labels.u8", dtype=np.uint8))
    counts = np.bincount(r.labels, minlength=3)
    assert counts[2] == r.record["wet"]["lost"] > 0 and counts[1] > 0
    assert r.record["command"] == "lidar wet"
    off = r.labels == 0
    kept = r.labels != 2
    assert np.array_equal(r.points[off[kept]], pts[off])  # off the ground: unchanged
    assert np.array_equal(brume.lidar.wet(pts, film=0.0).points, pts)
    with pytest.raises(ValueError, match="film"):
        brume.lidar.wet(pts)
    with pytest.raises(ValueError, match="film=-1"):
        brume.lidar.wet(pts, film=-1.0)
