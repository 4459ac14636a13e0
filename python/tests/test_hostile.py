"""Issue #51's reproducers found in Python: non-finite colour (refused as the
CLI refuses it, or replaced with nonfinite='zero'), the derived blur's bound
(the same check as the CLI's and `brume run`'s), a scan's validation."""
import numpy as np
import pytest

import brume
from conftest import scan


def test_nonfinite_colour_is_refused_as_on_the_cli(demo):
    """One NaN pixel became 7 186 NaN pixels out of brume.haze (the CLI
    refused it by default; Python had no nonfinite=)."""
    rgb = demo["rgb"].copy()
    rgb[40, 70, 1] = np.nan
    rgb[41, 70, 0] = np.inf
    for call in (lambda **k: brume.haze(rgb, demo["range"], visibility=300, **k),
                 lambda **k: brume.fog(rgb, demo["range"], fov_y=55, camera_height=1.6, lambda_=2, **k),
                 lambda **k: brume.blur(rgb, sigma=3, **k)):
        with pytest.raises(ValueError, match=r"rgb has 2 non-finite values \(NaN or inf\); the first is NaN at x 70, "
                                             r"y 40 \(row 0 at the top\), channel 1.*nonfinite='zero'"):
            call()
        r = call(nonfinite="zero")
        assert np.isfinite(r.rgb).all()
        assert r.record["inputs"]["rgb"]["nonfinite_replaced"] == 2
        assert r.record["inputs"]["rgb"]["copied"] is True
    # The caller's array is not touched; zero gives what an array with zeros gives.
    assert np.isnan(rgb[40, 70, 1])
    zeroed = np.nan_to_num(rgb, nan=0.0, posinf=0.0)
    a = brume.haze(rgb, demo["range"], visibility=300, nonfinite="zero")
    b = brume.haze(zeroed, demo["range"], visibility=300)
    assert np.array_equal(a.rgb, b.rgb)
    with pytest.raises(ValueError, match="nonfinite '.*' is not allowed; use one of: error, zero"):
        brume.haze(rgb, demo["range"], visibility=300, nonfinite="ignore")
    # The choices are the CLI's, in the docstring and the stub.
    assert "nonfinite" in brume.haze.__doc__


def test_derived_blur_bound_is_the_clis(demo):
    """haze's lambda 1e4 with the standard scheme returned values from -1e6
    to 5e5 (the iteration count overflowed); now the same Error as the CLI, in Python's words."""
    with pytest.raises(ValueError, match=r"sigma_max = .* px is .* times the image's diagonal .*lambda_=10000"):
        brume.haze(demo["rgb"], demo["range"], visibility=300, lambda_=1e4, scheme="standard")
    with pytest.raises(ValueError, match="sigma_max"):
        brume.fog(demo["rgb"], demo["range"], fov_y=55, camera_height=1.6, lambda_=1e9)


def test_scan_arrays_are_validated_as_files_are():
    """The layered fog wrote a NaN intensity for a point at 3e38 m; an array
    scan gets the validation a file's does."""
    pts = scan(200)
    pts[7] = (3e38, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match=r"point 7 lies 3e\+38 m from the sensor.*up to 10000 m"):
        brume.lidar.fog(pts, profile="exponential", density=0.05, sensor_height=1.7)
    pts[7] = (np.nan, 0.0, 0.0, 0.5)
    with pytest.raises(ValueError, match="point 7 has a non-finite x"):
        brume.lidar.fog(pts, visibility=40.0)


def test_stereo_fattening_without_a_second_view_is_refused(demo):
    """complete_stereo_fattening= guards the fusion with --stereo-right's
    view; arrays have none, so it would change nothing: refused in Python's
    words, as the CLI refuses --complete-stereo-fattening without a second
    view."""
    rgb = np.full((48, 64, 3), 0.4, np.float32)
    sparse = np.full((48, 64), np.nan, np.float32)
    sparse[24::4] = 8.0
    with pytest.raises(ValueError, match=r"complete_stereo_fattening guards the fusion"):
        brume.depth.complete(rgb, sparse, complete_stereo_fattening=3)
    with pytest.raises(ValueError, match=r"complete_stereo_fattening guards the fusion"):
        brume.haze(rgb, sparse, visibility=100, complete="on", complete_stereo_fattening=3)
    assert np.isfinite(brume.depth.complete(rgb, sparse).range[30]).all()
