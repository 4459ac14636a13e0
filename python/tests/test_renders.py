"""Blender's multilayer renders from Python (issue #50): the layer by keyword,
errors that name the keyword, the depth pass found by name, the camera in
millimetres as keywords, equal to the CLI bit for bit."""
import json

import numpy as np
import pytest

import brume
from conftest import ROOT, run_cli

RENDERS = ROOT / "tests" / "renders"


def side(name):
    return json.loads((RENDERS / f"{name}.json").read_text())


def test_read_image_takes_the_layer_by_keyword():
    with pytest.raises(ValueError, match=r"2 colour layers \(ViewLayer.AO, ViewLayer.Combined\).*layer="):
        brume.read_image(RENDERS / "cycles.exr")
    r = brume.read_image(RENDERS / "cycles.exr", layer="ViewLayer.Combined")
    assert r.rgb.shape == (48, 64, 3)
    assert r.file["layer"] == "ViewLayer.Combined"
    assert r.file["channels_read"][:3] == ["ViewLayer.Combined.R", "ViewLayer.Combined.G", "ViewLayer.Combined.B"]
    with pytest.raises(ValueError, match="no colour layer named 'Beauty'"):
        brume.read_image(RENDERS / "cycles.exr", layer="Beauty")
    with pytest.raises(TypeError, match="layer takes a str"):
        brume.read_image(RENDERS / "cycles.exr", layer=3)


@pytest.mark.parametrize("engine", ["cycles", "eevee"])
def test_haze_on_a_render_equals_the_cli_and_beer_lambert(engine, tmp_path):
    s = side(engine)
    cam = s["camera"]
    f = RENDERS / f"{engine}.exr"
    rgb = brume.read_image(f, layer="ViewLayer.Combined").rgb
    depth = brume.depth.convert(z=f, focal_length=cam["lens_mm"], sensor_width=cam["sensor_width_mm"],
                                lens_shift=(cam["shift_x"], cam["shift_y"]))
    assert "ViewLayer.Depth.Z" in json.dumps(depth.record)
    r = brume.haze(rgb, depth.range, visibility=100, lambda_=0)
    run_cli("haze", "--image", f, "--image-layer", "ViewLayer.Combined", "--z", f, "--focal-length", cam["lens_mm"],
            "--sensor-width", cam["sensor_width_mm"], "--lens-shift", f"{cam['shift_x']!r},{cam['shift_y']!r}",
            "--visibility", 100, "--lambda", 0, "--out", tmp_path / "o.exr", "--transmission", tmp_path / "t.exr")
    t = brume.depth.convert(range=tmp_path / "t.exr").range
    assert np.array_equal(r.transmission, t, equal_nan=True)
    # Beer-Lambert on the range (tests/test_renders.cpp holds the range to Blender's own projection).
    known = np.isfinite(depth.range)
    ref = np.exp(-3.912 * depth.range.astype(np.float64) / 100.0)
    assert known.sum() > 1000
    assert np.max(np.abs(r.transmission[known] - ref[known])) <= 2e-6

def test_the_camera_keywords_are_checked_as_the_flags():
    f = RENDERS / "cycles.exr"
    with pytest.raises(ValueError, match="sensor_width=MM"):
        brume.depth.convert(z=f, focal_length=35)
    with pytest.raises(TypeError, match="2 numbers"):
        brume.depth.convert(z=f, focal_length=35, sensor_width=36, lens_shift=0.1)
    with pytest.raises(ValueError, match="planar depth"):
        brume.depth.convert(range=f)
