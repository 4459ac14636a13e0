"""Wet ground from Python (issue #57): brume.lidar.wet, the scan `brume lidar wet`
writes, bit for bit; brume.wet, the image, the ground and the scan `brume wet`
writes on the demo scene, bit for bit, its job replayed, its errors in Python's
words; the Wet transform (keyed draws, lidar_target, replay) and wet's sampling."""
import json

import numpy as np
import pytest

import brume
import brume.transforms as T
from conftest import run_cli, scan

# The demo scene's camera (brume demo: 1.6 m up, 5 degrees down, 55 degrees vertical field of view).
POSE = dict(fov_y=55, camera_height=1.6, pitch=-5)


def same(a, b):
    assert a.shape == b.shape and a.dtype == b.dtype
    assert np.array_equal(a, b, equal_nan=True), f"max |diff| {np.nanmax(np.abs(a - b))}"


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


def test_wet_equals_cli_bit_for_bit(demo, tmp_path):
    """brume.wet on the demo's arrays: the image, the ground map and the scan of lidar= are
    `brume wet`'s with --lidar, bit for bit; the record's counts are the CLI's; its job repeats it."""
    d = demo["dir"]
    pts = ground_scan()
    pts.tofile(tmp_path / "in.bin")
    run_cli("wet", "--image", d / "clean.png", "--range", d / "range.exr", "--fov-y", 55, "--camera-height", 1.6,
            "--pitch", -5, "--film", 0.7, "--ground-albedo", 0.2, "--noise-floor", 2e-4,
            "--lidar", tmp_path / "in.bin", "--lidar-out", tmp_path / "out.bin", "--lidar-labels", tmp_path / "l.u8",
            "--out", tmp_path / "o.exr", "--bits", "float", "--record", tmp_path / "o.json")
    r = brume.wet(demo["rgb"], demo["range"], film=0.7, ground_albedo=0.2, noise_floor=2e-4, lidar=pts, **POSE)
    same(r.rgb, brume.read_image(tmp_path / "o.exr").rgb)
    same(r.lidar, np.fromfile(tmp_path / "out.bin", np.float32).reshape(-1, 4))
    assert np.array_equal(r.lidar_labels, np.fromfile(tmp_path / "l.u8", np.uint8))
    alone = brume.lidar.wet(pts, film=0.7, ground_albedo=0.2, noise_floor=2e-4)  # one film: the scan's own form
    same(r.lidar, alone.points)
    cli = json.loads((tmp_path / "o.json").read_text())
    for k in ("ground_pixels", "mirror_hits", "mirror_sky_pixels", "mirror_left_frame", "k_eff"):
        assert r.record["wet"][k] == cli["wet"][k], k
    assert r.ground.shape == r.rgb.shape[:2] and set(np.unique(r.ground)) <= {0.0, 1.0}
    assert int(r.ground.sum()) == r.record["wet"]["ground_pixels"] > 1000 and r.record["lidar_wet"]["lost"] == cli["lidar_wet"]["lost"]
    assert r.record["command"] == "wet" and r.record["job"]["lidar"] == {}
    again = brume.wet(demo["rgb"], demo["range"], job=json.loads(json.dumps(r.record["job"])), lidar=pts)
    same(again.rgb, r.rgb)
    same(again.lidar, r.lidar)
    no_scan = brume.wet(demo["rgb"], demo["range"], film=0.7, ground_albedo=0.2, **POSE)
    assert no_scan.lidar is None and no_scan.lidar_labels is None and "lidar" not in no_scan.record["job"]
    same(no_scan.rgb, r.rgb)
    # film 0: the image back, bit for bit
    same(brume.wet(demo["rgb"], demo["range"], film=0, **POSE).rgb, demo["rgb"])


def test_wet_errors_speak_python(demo):
    rgb, rng = demo["rgb"], demo["range"]
    cases = [
        (dict(POSE), "film"),                                      # the film is required
        (dict(POSE, film=-1), "film"),
        (dict(POSE, film=1, ground_albedo=1.5), "ground_albedo"),
        (dict(fov_y=55, film=1), "camera_height"),                 # the plane needs the camera's height
    ]
    for kw, word in cases:
        with pytest.raises(ValueError, match=word) as e:
            brume.wet(rgb, rng, **kw)
        assert "--" not in str(e.value), str(e.value)
        assert str(e.value).startswith("brume.wet(): "), str(e.value)  # the run's errors name the function too
    with pytest.raises(ValueError, match=r"\(N, 4\)"):
        brume.wet(rgb, rng, film=1, lidar=ground_scan()[:, :3], **POSE)
    with pytest.raises(TypeError, match="film"):
        brume.wet(rgb, rng, flim=1, **POSE)


def test_wet_sampling_and_transform(demo):
    """random_params draws the film, the albedo and the scan's seed per key; the Wet transform applies
    brume.wet with them, replays them, and wets the frame's scan with lidar_target."""
    a, b = brume.random_params("wet", 7, "frame/0"), brume.random_params("wet", 7, "frame/1")
    assert set(a) == {"film", "ground-albedo", "scan-seed"}
    assert 0.05 <= a["film"] < 2 and 0.05 <= a["ground-albedo"] < 0.25 and a["scan-seed"] != b["scan-seed"]
    assert a["scan-seed"] == int(T._unit(7, "frame/0", "scan-seed") * 2.0 ** 53)
    rgb, rng = demo["rgb"], demo["range"]
    pts = ground_scan()
    t = T.Wet(seed=7, lidar_target="points", **POSE)
    out = t(image=rgb, depth=rng, points=pts, key="frame/0")
    v = out["params"]["values"]
    assert v == a
    direct = brume.wet(rgb, rng, film=v["film"], ground_albedo=v["ground-albedo"], scan_seed=v["scan-seed"],
                       lidar=pts, **POSE)
    same(out["image"], direct.rgb)
    same(out["points"], direct.lidar)
    params = json.loads(json.dumps(out["params"]))
    again = T.Wet(seed=99, lidar_target="points", **POSE).replay(params)(image=rgb, depth=rng, points=pts)
    same(again["image"], out["image"])
    same(again["points"], out["points"])
    # refused when made, in Python's words: a range outside the table's, a transform without the plane
    with pytest.raises(ValueError, match="film"):
        T.Wet(film=(1, 200), **POSE)
    with pytest.raises(ValueError, match="camera_height"):
        T.Wet(fov_y=55)


def test_wet_ground_mask_equals_cli_bit_for_bit(demo, tmp_path):
    """ground_mask= is the CLI's --ground-mask: a bool array, the same mask as a float one and as a grey
    PNG file give the same image and ground bit for bit; the ground is the mask (not the plane's
    tolerance); a mask needs no camera_height; wrong sizes, integer and NaN masks are refused in
    Python's words."""
    d = demo["dir"]
    rgb, rng = demo["rgb"], demo["range"]
    h, w = rng.shape
    mask = np.zeros((h, w), bool)
    mask[h * 3 // 4:, : w // 2] = True  # the lower left quarter: part ground, part not
    brume.write_image(tmp_path / "mask.png", np.repeat(mask.astype(np.float32)[:, :, None], 3, axis=2), bits="8")
    run_cli("wet", "--image", d / "clean.png", "--range", d / "range.exr", "--fov-y", 55, "--camera-height", 1.6,
            "--pitch", -5, "--film", 0.7, "--ground-mask", tmp_path / "mask.png",
            "--out", tmp_path / "o.exr", "--bits", "float", "--ground", tmp_path / "g.exr",
            "--record", tmp_path / "o.json")
    r = brume.wet(rgb, rng, film=0.7, ground_mask=mask, **POSE)
    same(r.rgb, brume.read_image(tmp_path / "o.exr").rgb)
    cli = json.loads((tmp_path / "o.json").read_text())
    assert r.record["wet"]["ground_rule"] == cli["wet"]["ground_rule"] and "mask" in cli["wet"]["ground_rule"]
    assert r.record["wet"]["ground_pixels"] == cli["wet"]["ground_pixels"] == int(r.ground.sum())
    # the ground is the mask where the pixel's ray goes down to a finite range: the demo's lower left quarter
    assert not (r.ground[~mask] > 0).any() and r.ground[mask].mean() > 0.99
    assert r.record["inputs"]["ground_mask"]["marked"] == int(mask.sum())
    same(brume.wet(rgb, rng, film=0.7, ground_mask=mask.astype(np.float64) * 0.9, **POSE).rgb, r.rgb)
    off = ~mask
    assert np.array_equal(r.rgb[off], rgb[off])  # pixels off the mask unchanged
    nopose = brume.wet(rgb, rng, film=0.7, fov_y=55, pitch=-5, ground_mask=mask)  # no camera_height needed
    assert int(nopose.ground.sum()) > 0
    cases = [
        (dict(ground_mask=mask[:-1]), "ground_mask is"),
        (dict(ground_mask=mask.astype(np.uint8)), "ambiguous"),
        (dict(ground_mask=np.where(mask, np.nan, 0.0)), "NaN"),
    ]
    for kw, word in cases:
        with pytest.raises(ValueError, match=word) as e:
            brume.wet(rgb, rng, film=0.7, **POSE, **kw)
        assert "--" not in str(e.value) and "ground_mask" in str(e.value), str(e.value)
    with pytest.raises(ValueError, match="ground_mask=") as e:
        brume.wet(rgb, rng, film=0.7, fov_y=55)
    assert "--" not in str(e.value)


def test_wet_old_records_repeat_with_the_blocks_march(demo, tmp_path):
    """--mirror-march (since schema 4, before it "blocks"): a record written before it (its job without
    the key) repeats the blocks march, bit for bit; the default above-ground march is recorded, and its
    image differs from the blocks march only on the ground."""
    d = demo["dir"]
    common = ["wet", "--image", d / "clean.png", "--range", d / "range.exr", "--fov-y", 55, "--camera-height", 1.6,
              "--pitch", -5, "--film", 0.7, "--bits", "float"]
    run_cli(*common, "--out", tmp_path / "new.exr", "--record", tmp_path / "new.json")
    run_cli(*common, "--mirror-march", "blocks", "--out", tmp_path / "old.exr", "--record", tmp_path / "old.json")
    new = json.loads((tmp_path / "new.json").read_text())
    assert new["job"]["ground"]["mirror-march"] == "above-ground" and new["wet"]["mirror_march"] == "above-ground"
    old = json.loads((tmp_path / "old.json").read_text())
    del old["job"]["ground"]["mirror-march"]  # as written before the parameter existed
    (tmp_path / "before.json").write_text(json.dumps(old))
    run_cli("run", tmp_path / "before.json", "--out-dir", tmp_path / "again")
    again = json.loads((tmp_path / "again" / "old.json").read_text())
    assert again["job"]["ground"]["mirror-march"] == "blocks"
    same(brume.read_image(tmp_path / "again" / "old.exr").rgb, brume.read_image(tmp_path / "old.exr").rgb)
    a, b = brume.read_image(tmp_path / "new.exr").rgb, brume.read_image(tmp_path / "old.exr").rgb
    ground = brume.wet(demo["rgb"], demo["range"], film=0.7, **POSE).ground > 0.5
    assert np.array_equal(a[~ground], b[~ground])


def test_wet_warns_when_the_plane_misses_the_ground(demo, tmp_path):
    """A pose whose plane holds under 2 % of the known pixels that look down (a camera said to be 6 m
    up on the demo scene, 1.6 m up) wets almost nothing: the record's wet block warns, naming the
    height and the fix, and the command line prints it; the demo's own pose gives no warning."""
    rgb, rng = demo["rgb"], demo["range"]
    assert "warnings" not in brume.wet(rgb, rng, film=1, **POSE).record["wet"]
    r = brume.wet(rgb, rng, film=1, **dict(POSE, camera_height=6))
    assert r.record["wet"]["ground_pixels"] == 0
    (w,) = r.record["wet"]["warnings"]
    assert "6 m below the camera" in w and "mask" in w, w
    # ... and names the plane the lower half's points lie on: the demo's own pose (1.6 m, 5 degrees
    # down, level), within the fit's noise (5 cm, 0.2 degree: a sampled RANSAC refined by least squares)
    import re
    m = re.search(r"lie on a plane ([-0-9.e]+) m below the camera at pitch ([-0-9.e]+) deg, roll ([-0-9.e]+) deg", w)
    assert m, w
    height, pitch, roll = map(float, m.groups())
    assert abs(height - 1.6) < 0.05 and abs(pitch + 5) < 0.2 and abs(roll) < 0.2, w
    d = demo["dir"]
    out = run_cli("wet", "--image", d / "clean.png", "--range", d / "range.exr", "--fov-y", 55, "--camera-height", 6,
                  "--pitch", -5, "--film", 1, "--out", tmp_path / "w.png")
    assert "brume wet: warning: the ground plane 6 m below the camera" in out.stderr, out.stderr
