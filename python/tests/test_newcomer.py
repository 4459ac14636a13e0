"""The Python API as a newcomer meets it (issue #54): transforms that check
every draw when they are made, messages in Python's words, scenes at any
scale (--scene-scale), disparity with an offset, and the transforms in a
torch DataLoader over real frames."""
import json
import math
import re

import numpy as np
import pytest

import brume
from brume import transforms as T

from conftest import data_folder, run_cli

# A flag as the command line spells it ("--camera-height"): a Python message never holds one.
CLI_FLAG = re.compile(r"(?<![\w-])--[a-z]")


def _scene(h=48, w=64, seed=0):
    g = np.random.default_rng(seed)
    rgb = g.random((h, w, 3), dtype=np.float32)
    yy, xx = np.mgrid[0:h, 0:w]
    rng = (20.0 + 3.0 * xx + 0.5 * yy).astype(np.float32)
    return rgb, rng


def _message(call):
    with pytest.raises((ValueError, TypeError)) as e:
        call()
    return str(e.value)


# ---- transforms check when made ----------------------------------------------------------------
def test_fog_without_the_camera_height_fails_when_made_in_python_words():
    """The issue's case: accepted, then failing in a DataLoader worker with the
    CLI's spelling. Now the constructor checks what every draw needs."""
    m = _message(lambda: T.Fog(seed=8, p=0.5, fov_y=40))
    assert m.startswith("brume.transforms.Fog(): profile='exponential'") and "camera_height=METRES" in m, m
    assert "view_matrix=FILE" in m and not CLI_FLAG.search(m), m
    T.Fog(seed=8, p=0.5, fov_y=40, camera_height=1.6)  # what it asked for
    m = _message(lambda: T.Fog(camera_height=1.6))  # the rays' directions: the intrinsics
    assert "fov_x" in m and "fx" in m and not CLI_FLAG.search(m), m
    T.Fog(profile="constant")  # a medium the same at every height needs no camera


def test_a_draw_that_would_fail_is_refused_when_made():
    """Every combination of the distributions' ends and choices is checked:
    a profile that may be drawn exponential needs the camera height; ranges
    whose ends cross fail on the crossing draw; the message says which draw."""
    m = _message(lambda: T.Fog(profile=T.choice("constant", "exponential"), fov_y=40))
    assert "camera_height=METRES" in m and "when the draw gives" in m and "profile='exponential'" in m, m
    # ... and a camera height is a pose the constant draws would ignore: no such transform can run
    m = _message(lambda: T.Fog(profile=T.choice("constant", "exponential"), fov_y=40, camera_height=1.6))
    assert "camera_height poses the camera, but profile='constant'" in m and "when the draw gives" in m, m
    m = _message(lambda: T.Fog(profile="ramp", ramp_bottom=(0, 60), ramp_top=(50, 100), fov_y=40,
                               camera_height=1.6))
    assert "ramp_top=50 must exceed ramp_bottom=60" in m and "when the draw gives" in m, m
    T.Fog(profile="ramp", ramp_bottom=(0, 40), ramp_top=(50, 100), fov_y=40, camera_height=1.6)
    # Depth of field: the CoC at infinity replaces the lens, so planar depth needs the intrinsics.
    T.DepthOfField()  # the default lens (50 mm on 36 mm) gives fx
    m = _message(lambda: T.DepthOfField(coc_infinity=8))
    assert "planar depth" in m and "fx" in m and "focal_length" in m and not CLI_FLAG.search(m), m
    T.DepthOfField(coc_infinity=8, fov_x=60)
    # A combination the run would ignore: kappa_s and the drawn visibility's albedo are dropped, lambda stays.
    m = _message(lambda: T.Haze(visibility=300, kappa_s=0.5))
    assert "kappa" in m and not CLI_FLAG.search(m), m


def test_the_checks_are_the_command_lines(tmp_path, demo):
    """The transform's refusal and the CLI's are the same check, each in its own words."""
    r = __import__("subprocess").run([__import__("conftest").cli_path(), "fog", "--image", demo["dir"] / "clean.png",
                                      "--range", demo["dir"] / "range.exr", "--fov-y", "40", "--out",
                                      tmp_path / "x.png"], capture_output=True, text=True)
    assert r.returncode != 0 and "give --camera-height METRES" in r.stderr, r.stderr  # the CLI keeps its own
    m = _message(lambda: T.Fog(fov_y=40))
    assert "give camera_height=METRES" in m


def test_a_fog_made_valid_runs_in_dataloader_workers():
    torch = pytest.importorskip("torch")
    from torch.utils.data import DataLoader

    class Frames(torch.utils.data.Dataset):
        def __init__(self):
            self.t = T.Fog(seed=8, p=0.5, fov_y=40, camera_height=1.6)

        def __len__(self):
            return 4

        def __getitem__(self, i):
            rgb, rng = _scene(seed=i)
            return self.t(image=rgb, depth=rng, key=f"f{i}")["image"]

    dl = DataLoader(Frames(), batch_size=2, num_workers=2, multiprocessing_context="fork")
    assert sum(b.shape[0] for b in dl) == 4


# ---- messages in Python's words --------------------------------------------------------------------
def test_every_message_uses_keyword_spelling(demo):
    """The exception translator rewrites the library's flags as keywords from
    the tables, a value after a flag as the keyword's argument."""
    rgb, rng = demo["rgb"], demo["range"]
    cases = {
        lambda: brume.haze(rgb, rng, visibility=-5): r"brume\.haze\(\): visibility=-5 is not allowed.*\(0, inf\)",
        lambda: brume.haze(rgb, rng, visibility=300, kappa_s=0.5): r"kappa_s",
        lambda: brume.fog(rgb, rng, fov_y=40): r"profile='exponential'.*give camera_height=METRES",
        lambda: brume.dof(rgb, rng, fov_x=60): r"focus_distance is required",
        lambda: brume.haze(rgb, rng, lambda_=-1): r"lambda_=-1",
        lambda: brume.haze(rgb, rng, reference=True, backend="gpu"): r"reference",
        lambda: brume.random_params("haze", 0, "k", visibility="uniform(-1, 5)"): r"visibility='uniform\(-1, 5\)'",
        lambda: brume.haze(rgb, rng, visibility=60, lidar=np.float32([[1, 2, 3, 200]] * 5)):
            r"for a scan already in \[0, 255\] give lidar_intensity_scale=1",
        lambda: brume.haze(rgb, rng, visibility="far"): r"keyword visibility takes a number",
    }
    for call, pattern in cases.items():
        m = _message(call)
        assert re.search(pattern, m), (pattern, m)
        assert not CLI_FLAG.search(m), m


def test_the_spelling_comes_from_the_tables():
    """A word after a flag is its value only when the declaration takes it:
    a choice's name (quoted), a number, a placeholder; not a verb."""
    m = _message(lambda: brume.fog(np.zeros((8, 8, 3), np.float32), np.ones((8, 8), np.float32), profile="table"))
    assert "profile='table' needs table=FILE.csv" in m, m


# ---- scenes at any scale -------------------------------------------------------------------------
def test_scene_scale_scales_the_lengths_by_the_frames_median_range(demo, tmp_path):
    rgb, rng = demo["rgb"], demo["range"]
    median = float(np.median(rng[np.isfinite(rng) & (rng > 0)]))
    r = brume.haze(rgb, rng, visibility=300, scene_scale=15, threads=1)
    s = r.record["scene_scale"]
    assert s["reference_median_range_m"] == 15 and s["median_range_m"] == pytest.approx(median, rel=1e-6)
    assert s["factor"] == pytest.approx(median / 15, rel=1e-12)
    assert s["scaled"]["visibility"] == {"given": 300, "applied": pytest.approx(300 * median / 15, rel=1e-12)}
    assert r.record["job"]["haze"]["visibility"] == 300 and r.record["job"]["scene"]["scene-scale"] == 15
    same = brume.haze(rgb, rng, visibility=s["scaled"]["visibility"]["applied"], threads=1)
    np.testing.assert_array_equal(r.rgb, same.rgb)
    np.testing.assert_array_equal(brume.rerun(r.record, rgb, rng).rgb, r.rgb)
    # The command line: the same flag, the same bits, the same record block; brume run repeats it.
    run_cli("haze", "--image", demo["dir"] / "clean.png", "--range", demo["dir"] / "range.exr", "--visibility", 300,
            "--scene-scale", 15, "--out", tmp_path / "h.pfm", "--record", tmp_path / "h.json", "--threads", 1)
    cli = json.loads((tmp_path / "h.json").read_text())
    assert cli["scene_scale"]["factor"] == pytest.approx(s["factor"], rel=1e-12)
    np.testing.assert_array_equal(brume.read_image(tmp_path / "h.pfm").rgb, r.rgb)
    # fog's density and depth of field's focus distance
    f = brume.fog(rgb, rng, profile="constant", density=0.02, scene_scale=15, threads=1)
    assert f.record["scene_scale"]["scaled"]["density"]["applied"] == pytest.approx(0.02 * 15 / median)
    d = brume.dof(rgb, rng, focus_distance=30, coc_infinity=6, fov_x=60, scene_scale=15, threads=1)
    assert d.record["scene_scale"]["scaled"]["focus-distance"]["applied"] == pytest.approx(30 * median / 15)
    # The scan's fog is in metres: refused with a LiDAR scan.
    m = _message(lambda: brume.haze(rgb, rng, visibility=300, scene_scale=15,
                                    lidar=np.ones((10, 4), np.float32)))
    assert "scene_scale" in m and not CLI_FLAG.search(m), m


def _middlebury(name="Art"):
    d = data_folder() / "middlebury2005_thirdsize" / name
    if not (d / "disp1.png").exists():
        pytest.skip(f"the Middlebury 2005 data is absent ({d})")
    return d


def _art():
    d = _middlebury()
    dmin = float((d / "dmin.txt").read_text().split()[0])
    rng = brume.depth.convert(disparity=d / "disp1.png", fx=3740 / 3, baseline=0.16, disparity_scale=1 / 3,
                              disparity_offset=dmin / 3).range
    return brume.read_image(d / "view1.png").rgb, rng, dmin


def test_scene_scale_on_an_indoor_frame(demo):
    """On Middlebury Art (a room, median range 1.8 m) the default draws give
    almost no haze; scaled to the frame, at least twice the change on
    average, and the transmission at the median range is the reference
    frame's: the same for the room and the demo's street, draw by draw."""
    rgb, rng, _ = _art()
    rgb, rng = rgb[::2, ::2].copy(), rng[::2, ::2].copy()  # (a quarter of the pixels: the test's time)
    plain, scaled = T.Haze(seed=3), T.Haze(seed=3, scene_scale=15)
    shift_plain, shift_scaled, t_room, t_street = [], [], [], []
    for i in range(12):
        key = f"art/{i}"
        a, b = plain(image=rgb, depth=rng, key=key), scaled(image=rgb, depth=rng, key=key)
        assert a["params"]["values"] == b["params"]["values"]  # one draw, as brume sample gives it
        shift_plain.append(np.abs(a["image"] - rgb).mean())
        shift_scaled.append(np.abs(b["image"] - rgb).mean())
        for rec, out in ((b["params"]["record"], t_room),
                         (scaled(image=demo["rgb"], depth=demo["range"], key=key)["params"]["record"], t_street)):
            s = rec["scene_scale"]
            out.append(math.exp(-3.912 * s["median_range_m"] / s["scaled"]["visibility"]["applied"]))
    ratio = np.mean(shift_scaled) / np.mean(shift_plain)
    print(f"Art: mean |change| {np.mean(shift_plain):.4f} unscaled, {np.mean(shift_scaled):.4f} scaled ({ratio:.1f}x)")
    assert ratio >= 2.0
    np.testing.assert_allclose(t_room, t_street, rtol=1e-9)
    # ... which is that of an unscaled frame whose median range is the reference, 15 m
    v = [brume.random_params("haze", 3, f"art/{i}")["visibility"] for i in range(12)]
    np.testing.assert_allclose(t_room, [math.exp(-3.912 * 15 / x) for x in v], rtol=1e-9)


def test_a_constant_profile_fog_draws_its_density():
    d = {brume.random_params("fog", 0, f"k{i}", profile="constant")["density"] for i in range(6)}
    assert len(d) == 6 and all(0.002 <= x < 0.08 for x in d)
    p = brume.random_params("fog", 0, "k", profile="constant")
    assert "falloff" not in p  # (a constant profile has none)
    assert "density" not in brume.random_params("fog", 0, "k", profile="table", table="t.csv")


def test_sample_and_batch_draw_what_python_draws(tmp_path, demo):
    """brume sample (which has no frame) prints the draw the transform makes; the run scales it."""
    r = run_cli("sample", "--effect", "haze", "--seed", 3, "--key", "art/0")
    printed = json.loads(r.stdout[r.stdout.index("{"):])
    assert printed["params"]["visibility"] == brume.random_params("haze", 3, "art/0")["visibility"]
    t = T.Haze(seed=3, scene_scale=15)
    rgb, rng = _scene()
    rec = t(image=rgb, depth=rng, key="art/0")["params"]["record"]
    assert rec["scene_scale"]["scaled"]["visibility"]["given"] == printed["params"]["visibility"]
    # a batch frame with --param scene-scale=15 draws the same value and scales it by its frame's median range
    (tmp_path / "m.csv").write_text(f"key,image,range\nart/0,{demo['dir'] / 'clean.png'},{demo['dir'] / 'range.exr'}\n")
    # (a batch draws the parameters its manifest or --param give: the sampler's default for visibility, given)
    run_cli("batch", "--manifest", tmp_path / "m.csv", "--out-dir", tmp_path / "out", "--effect", "haze", "--seed", 3,
            "--param", "scene-scale=15", "--param", "visibility=" + printed["sampling"]["specs"]["visibility"],
            "--quiet")
    b = json.loads((tmp_path / "out" / "art" / "0.json").read_text())
    s = b["scene_scale"]
    assert b["job"]["haze"]["visibility"] == s["scaled"]["visibility"]["given"] == printed["params"]["visibility"]
    median = float(np.median(demo["range"][np.isfinite(demo["range"]) & (demo["range"] > 0)]))
    assert s["median_range_m"] == pytest.approx(median, rel=1e-6)
    assert s["scaled"]["visibility"]["applied"] == pytest.approx(printed["params"]["visibility"] * median / 15, rel=1e-12)
    py = T.Haze(seed=3, scene_scale=15)(image=demo["rgb"], depth=demo["range"], key="art/0")["params"]["record"]
    assert py["scene_scale"]["scaled"]["visibility"] == s["scaled"]["visibility"]


# ---- disparity with an offset ------------------------------------------------------------------
def test_disparity_keywords_as_depth_convert():
    rgb, rng, dmin = _art()
    d = _middlebury()
    from PIL import Image
    disp = np.asarray(Image.open(d / "disp1.png"))  # uint8, 0 unknown
    t = T.Haze(visibility=20, depth_kind="disparity", fx=3740 / 3, baseline=0.16, disparity_scale=1 / 3,
               doffs=dmin / 3, seed=1)
    a = t(image=rgb, depth=disp, key="k")
    b = T.Haze(visibility=20, seed=1)(image=rgb, depth=rng, key="k")
    np.testing.assert_allclose(a["image"], b["image"], atol=2e-5)
    assert T.Haze(depth_kind="disparity", fx=1, baseline=1, disparity_offset=2).disparity == {"disparity_offset": 2.0}
    with pytest.raises(TypeError, match="disparity_offset and doffs"):
        T.Haze(depth_kind="disparity", fx=1, baseline=1, disparity_offset=2, doffs=2)
    with pytest.raises(ValueError, match="doffs|disparity_offset"):
        T.Haze(doffs=2)  # a range takes no disparity offset
    with pytest.raises(ValueError, match="baseline"):
        T.Haze(depth_kind="disparity", fx=1)


def test_disparity_with_a_calib_file():
    d = data_folder() / "eth3d_two_view" / "terrace"
    if not (d / "calib.txt").exists():
        pytest.skip(f"the ETH3D data is absent ({d})")
    rgb = brume.read_image(d / "im0.png").rgb
    rng = brume.depth.convert(disparity=d / "disp0.pfm", calib=d / "calib.txt").range
    disp = brume.read_image(d / "disp0.pfm", transfer="linear").rgb[..., 0]
    t = T.Haze(visibility=20, depth_kind="disparity", calib=d / "calib.txt", seed=1)
    a = t(image=rgb, depth=disp, key="k")
    b = T.Haze(visibility=20, seed=1)(image=rgb, depth=rng, key="k")
    np.testing.assert_allclose(a["image"], b["image"], atol=2e-5)
    with pytest.raises(ValueError, match="calib=.*drop fx"):
        T.Haze(depth_kind="disparity", calib=d / "calib.txt", fx=100)
    # fog and depth of field take the calibration's camera too
    T.Fog(depth_kind="disparity", calib=d / "calib.txt", camera_height=1.6)


def test_dataloader_two_workers_over_real_frames():
    """The newcomer's trial: a DataLoader with two forked workers over
    Middlebury and ETH3D frames (disparity given as it is stored), one
    transform per camera, scaled to each scene; the samples equal those of
    the main process."""
    torch = pytest.importorskip("torch")
    from torch.utils.data import DataLoader
    root = data_folder()
    mb, eth = root / "middlebury2005_thirdsize", root / "eth3d_two_view"
    if not (mb / "Art" / "disp1.png").exists() or not (eth / "terrace" / "calib.txt").exists():
        pytest.skip("the Middlebury 2005 or ETH3D data is absent")
    from PIL import Image

    class Frames(torch.utils.data.Dataset):
        def __init__(self):
            self.items = []
            for name in ("Art", "Books"):
                dmin = float((mb / name / "dmin.txt").read_text().split()[0])
                t = T.Fog(depth_kind="disparity", fx=3740 / 3, baseline=0.16, disparity_scale=1 / 3,
                          doffs=dmin / 3, camera_height=1.2, scene_scale=15, seed=5)
                self.items.append((f"mb/{name}", mb / name / "view1.png", mb / name / "disp1.png", t))
            for name in ("terrace", "playground_1l"):
                t = T.Fog(depth_kind="disparity", calib=eth / name / "calib.txt", camera_height=1.6, scene_scale=15,
                          seed=5)
                self.items.append((f"eth/{name}", eth / name / "im0.png", eth / name / "disp0.pfm", t))

        def __len__(self):
            return len(self.items)

        def __getitem__(self, i):
            key, im, disp, t = self.items[i]
            img = np.asarray(Image.open(im).convert("RGB"))
            d = (np.asarray(Image.open(disp)) if disp.suffix == ".png"
                 else brume.read_image(disp, transfer="linear").rgb[..., 0].copy())
            out = t(image=img, depth=d, key=key)
            return torch.from_numpy(out["image"].astype(np.float32)).mean(), json.dumps(out["params"]["values"])

    ds = Frames()
    main = [ds[i] for i in range(len(ds))]
    got = []
    for mean, values in DataLoader(ds, batch_size=1, num_workers=2, multiprocessing_context="fork"):
        got.append((float(mean[0]), values[0]))
    assert [(float(m), v) for m, v in main] == got
