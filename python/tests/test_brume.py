"""brume's Python module against the CLI (bit for bit on the CPU backend),
its zero-copy inputs, its errors, the GIL and threads, files, the GPU."""
import math
import os
import subprocess
import sys
import threading

import numpy as np
import pytest

import brume
from brume import _brume
from conftest import assert_gil_released, cli_path, require_data, run_cli


def read_map(path, **kw):
    """A 1-channel file as brume reads it (raw values; integer files: counts with depth_scale=1)."""
    return brume.depth.convert(range=path, **kw).range


def same(a, b):
    """Bit-identical, NaN where NaN (the CPU backend's promise)."""
    assert a.shape == b.shape and a.dtype == b.dtype
    assert np.array_equal(a, b, equal_nan=True), f"max |diff| {np.nanmax(np.abs(a - b))}"


# ---- every function against the CLI on the same inputs (CPU: bit-identical) ----------------
def test_haze_equals_cli(demo, tmp_path):
    d = demo["dir"]
    run_cli("haze", "--image", d / "clean.png", "--range", d / "range.exr", "--visibility", 3000, "--albedo", 0.9,
            "--lambda", 6, "--out", tmp_path / "o.exr", "--bits", "float", "--transmission", tmp_path / "t.exr",
            "--scale-map", tmp_path / "s.exr", "--threads", 2)
    r = brume.haze(demo["rgb"], demo["range"], visibility=3000, albedo=0.9, lambda_=6, threads=2)
    same(r.rgb, brume.read_image(tmp_path / "o.exr").rgb)
    same(r.transmission, read_map(tmp_path / "t.exr"))
    same(r.scale, read_map(tmp_path / "s.exr"))
    # the record keeps the flag's name and the values actually used
    assert r.record["job"]["haze"]["lambda"] == 6
    assert r.record["job"]["haze"]["visibility"] == 3000
    assert r.record["haze"] == brume.read_image(tmp_path / "o.exr").record["haze"]


def test_aerial_equals_cli(demo, tmp_path):
    d = demo["dir"]
    run_cli("aerial", "--image", d / "clean.png", "--range", d / "range.exr", "--turbidity", 8, "--lambda", 4,
            "--out", tmp_path / "o.exr", "--bits", "float", "--attenuation", tmp_path / "a.exr")
    r = brume.aerial(demo["rgb"], demo["range"], turbidity=8, **{"lambda": 4})
    same(r.rgb, brume.read_image(tmp_path / "o.exr").rgb)
    same(r.attenuation, brume.read_image(tmp_path / "a.exr").rgb)


def test_aerial_slant_path_equals_cli(demo, tmp_path):
    # issue #59: the slant path from the pose (fov_y=, pitch=, roll=) is the CLI's, bit for bit
    d = demo["dir"]
    run_cli("aerial", "--image", d / "clean.png", "--range", d / "range.exr", "--turbidity", 6, "--altitude", 800,
            "--path", "slant", "--fov-y", 55, "--pitch", -5, "--roll", 2, "--out", tmp_path / "o.exr",
            "--bits", "float", "--attenuation", tmp_path / "a.exr")
    r = brume.aerial(demo["rgb"], demo["range"], turbidity=6, altitude=800, path="slant", fov_y=55, pitch=-5, roll=2)
    same(r.rgb, brume.read_image(tmp_path / "o.exr").rgb)
    same(r.attenuation, brume.read_image(tmp_path / "a.exr").rgb)
    assert r.record["aerial"]["derived"]["slant_path"]["dh_min_m"] < 0  # the path falls towards the ground
    # --airlight horizon: a word where a colour goes, as on the command line
    run_cli("aerial", "--image", d / "clean.png", "--range", d / "range.exr", "--airlight", "horizon", "--remove",
            "--out", tmp_path / "h.exr", "--bits", "float")
    h = brume.aerial(demo["rgb"], demo["range"], airlight="horizon", remove=True)
    same(h.rgb, brume.read_image(tmp_path / "h.exr").rgb)
    assert h.record["job"]["aerial"]["airlight"] == "horizon"
    assert h.record["aerial"]["derived"]["airlight_where"]["pixels"] >= 16
    with pytest.raises(TypeError, match="'horizon'"):
        brume.aerial(demo["rgb"], demo["range"], airlight="sunset")
    with pytest.raises(ValueError, match="pitch orients.*path=.slant.") as e:
        brume.aerial(demo["rgb"], demo["range"], pitch=3)
    assert "--" not in str(e.value)


def test_fog_equals_cli(demo, tmp_path):
    d = demo["dir"]
    args = dict(fov_y=55, camera_height=1.6, pitch=-5, profile="band", density=0.03, band_center=25,
                band_half_width=12, lambda_=3, airlight=(0.78, 0.79, 0.81))
    run_cli("fog", "--image", d / "clean.png", "--range", d / "range.exr", "--fov-y", 55, "--camera-height", 1.6,
            "--pitch", -5, "--profile", "band", "--density", 0.03, "--band-center", 25, "--band-half-width", 12,
            "--lambda", 3, "--airlight", "0.78,0.79,0.81", "--out", tmp_path / "o.exr", "--bits", "float",
            "--optical-depth", tmp_path / "f.exr")
    r = brume.fog(demo["rgb"], demo["range"], **args)
    same(r.rgb, brume.read_image(tmp_path / "o.exr").rgb)
    same(r.optical_depth, read_map(tmp_path / "f.exr"))


def test_dof_equals_cli(demo, tmp_path):
    d = demo["dir"]
    run_cli("dof", "--image", d / "clean.png", "--range", d / "range.exr", "--focus-distance", 3.9,
            "--coc-infinity", 14.4, "--fov-y", 55, "--out", tmp_path / "o.exr", "--bits", "float",
            "--scale-map", tmp_path / "s.exr")
    r = brume.dof(demo["rgb"], demo["range"], focus_distance=3.9, coc_infinity=14.4, fov_y=55)
    same(r.rgb, brume.read_image(tmp_path / "o.exr").rgb)
    same(r.scale, read_map(tmp_path / "s.exr"))


def test_blur_equals_cli(demo, tmp_path):
    d = demo["dir"]
    run_cli("blur", "--image", d / "clean.png", "--sigma", 4, "--out", tmp_path / "o.exr", "--bits", "float")
    same(brume.blur(demo["rgb"], sigma=4).rgb, brume.read_image(tmp_path / "o.exr").rgb)
    # a per-pixel scale map, from an array and from the file
    smap = np.linspace(1, 6, demo["rgb"].shape[1], dtype=np.float32)[None, :].repeat(demo["rgb"].shape[0], 0)
    brume.write_image(tmp_path / "map.exr", smap)
    run_cli("blur", "--image", d / "clean.png", "--scale-map", tmp_path / "map.exr", "--out", tmp_path / "m.exr",
            "--bits", "float")
    same(brume.blur(demo["rgb"], smap).rgb, brume.read_image(tmp_path / "m.exr").rgb)


def test_depth_convert_equals_cli(data_dir, tmp_path):
    art = require_data(data_dir / "middlebury2005_thirdsize" / "Art")
    flags = dict(fx=1246.667, baseline=0.16, disparity_scale=0.3333333, disparity_offset=66.667)
    for kind in ("range", "z"):
        run_cli("depth", "convert", "--disparity", art / "disp1.png", "--fx", 1246.667, "--baseline", 0.16,
                "--disparity-scale", 0.3333333, "--disparity-offset", 66.667, "--kind", kind,
                "--out", tmp_path / f"{kind}.exr")
        r = brume.depth.convert(disparity=art / "disp1.png", kind=kind, **flags)
        same(r[kind], read_map(tmp_path / f"{kind}.exr"))
    assert 1.3 < np.nanmin(r.z) and np.nanmax(r.z) < 2.3  # Art: 1.41-2.19 m (data/SOURCES.md)


def test_depth_stereo_equals_cli(data_dir, tmp_path):
    eth = data_dir / "eth3d_two_view" / "terrace"
    require_data(eth / "im1.png")
    run_cli("depth", "stereo", "--left", eth / "im0.png", "--right", eth / "im1.png", "--calib", eth / "calib.txt",
            "--out", tmp_path / "d.pfm", "--confidence", tmp_path / "c.pfm")
    r = brume.depth.stereo(left=eth / "im0.png", right=eth / "im1.png", calib=eth / "calib.txt")
    same(r.disparity, read_map(tmp_path / "d.pfm"))
    same(r.confidence, read_map(tmp_path / "c.pfm"))
    assert r.record["stereo"]["rectification"]["checked"]
    assert 0.5 < np.isfinite(r.disparity).mean() <= 1.0


def test_depth_prepare_equals_cli(demo, tmp_path):
    d = demo["dir"]
    run_cli("depth", "prepare", "--range", d / "range.exr", "--sky-margin", 4, "--out", tmp_path / "p.exr",
            "--masks", tmp_path / "m")
    r = brume.depth.prepare(demo["range"], sky_margin=4)
    same(r.range, read_map(tmp_path / "p.exr"))
    assert np.array_equal(r.sky_mask > 0.5, read_map(tmp_path / "m" / "sky.png", depth_scale=1) > 127)
    assert np.isfinite(r.range).all() and np.isnan(demo["range"]).any()


def test_sky_render_and_fit_equal_cli(tmp_path):
    run_cli("sky", "render", "--turbidity", 4, "--sun-zenith", 40, "--sun-azimuth", 120, "--width", 96,
            "--height", 48, "--out", tmp_path / "sky.exr")
    r = brume.sky.render(turbidity=4, sun_zenith=40, sun_azimuth=120, width=96, height=48)
    same(r.rgb, brume.read_image(tmp_path / "sky.exr").rgb)
    run_cli("sky", "fit", "--image", tmp_path / "sky.exr", "--sun-zenith", 40, "--sun-azimuth", 120,
            "--out", tmp_path / "fit.json")
    import json
    cli = json.loads((tmp_path / "fit.json").read_text())
    f = brume.sky.fit(np.nan_to_num(r.rgb), sun_zenith=40, sun_azimuth=120)
    assert f.turbidity == cli["turbidity"]
    assert abs(f.turbidity - 4) < 0.05  # the fit recovers the rendered turbidity (noise-free sky)


# ---- inputs: zero copy, conversions -------------------------------------------------------------
def test_float32_is_read_in_place():
    rgb = np.random.default_rng(1).random((64, 80, 3), dtype=np.float32)
    brume.blur(rgb, sigma=2)
    seen = _brume._debug_last_inputs()["rgb"]
    assert seen == {"address": rgb.ctypes.data, "copied": False, "how": "view"}
    # a crop and the RGB of an RGBA buffer are strided views: still no copy, same pixels
    crop = rgb[5:50, 7:70]
    r_crop = brume.blur(crop, sigma=2).rgb
    assert _brume._debug_last_inputs()["rgb"]["address"] == crop.ctypes.data
    assert not _brume._debug_last_inputs()["rgb"]["copied"]
    same(r_crop, brume.blur(np.ascontiguousarray(crop), sigma=2).rgb)
    rgba = np.concatenate([rgb, np.full((64, 80, 1), 7, np.float32)], axis=2)
    r_rgba = brume.blur(rgba, sigma=2).rgb
    assert _brume._debug_last_inputs()["rgb"] == {"address": rgba.ctypes.data, "copied": False, "how": "view"}
    same(r_rgba, brume.blur(rgb, sigma=2).rgb)


def test_haze_reads_rgb_and_range_in_place(demo):
    rgb, rng = demo["rgb"], demo["range"]
    ref = brume.haze(rgb, rng, visibility=900)
    seen = _brume._debug_last_inputs()
    assert seen["rgb"] == {"address": rgb.ctypes.data, "copied": False, "how": "view"}
    assert seen["range"] == {"address": rng.ctypes.data, "copied": False, "how": "view"}
    assert ref.record["inputs"]["rgb"]["copied"] is False
    # strided views (RGBA buffer, a range inside a wider array) give the same bits
    rgba = np.concatenate([rgb, np.ones(rgb.shape[:2] + (1,), np.float32)], axis=2)
    wide = np.zeros((rng.shape[0], rng.shape[1] + 9), np.float32)
    wide[:, 4:-5] = rng
    r = brume.haze(rgba, wide[:, 4:-5], visibility=900)
    assert not any(v["copied"] for v in _brume._debug_last_inputs().values())
    same(r.rgb, ref.rgb)
    same(r.transmission, ref.transmission)


# Every effect and tool that takes arrays, with the keywords of a quick run.
DENSE_CALLS = {
    "aerial": lambda rgb, rng: brume.aerial(rgb, rng, turbidity=3, lambda_=2),
    "fog": lambda rgb, rng: brume.fog(rgb, rng, fov_y=55, camera_height=1.6, density=0.03, lambda_=2),
    "dof": lambda rgb, rng: brume.dof(rgb, rng, focus_distance=3.9, coc_infinity=6, fov_y=55),
    "depth.prepare": lambda rgb, rng: brume.depth.prepare(rng),
    "sky.fit": lambda rgb, rng: brume.sky.fit(np.nan_to_num(rgb), sun_zenith=40, sun_azimuth=120),
}


@pytest.mark.parametrize("name", list(DENSE_CALLS))
def test_every_function_reads_c_contiguous_float32_in_place(demo, name):
    """aerial, fog, dof, depth.prepare and sky.fit read a C-contiguous float32
    array where numpy keeps it (the address the library read is the array's,
    nothing copied), as haze and blur do; a strided one (the RGB of an RGBA
    buffer, a range inside a wider array) is copied once, says so, and gives
    the same bits (the copy holds the same floats)."""
    call = DENSE_CALLS[name]
    rgb = np.ascontiguousarray(demo["rgb"])
    rng = np.ascontiguousarray(demo["range"])
    if name == "sky.fit":  # its rgb is the array given to it
        rgb = np.nan_to_num(demo["rgb"])
        call = lambda _rgb, _rng: brume.sky.fit(_rgb, sun_zenith=40, sun_azimuth=120)  # noqa: E731
    ref = call(rgb, rng)
    seen = _brume._debug_last_inputs()
    inputs = {"depth.prepare": {"range": rng}, "sky.fit": {"rgb": rgb}}.get(name, {"rgb": rgb, "range": rng})
    assert set(seen) == set(inputs)
    for arg, arr in inputs.items():
        assert seen[arg] == {"address": arr.ctypes.data, "copied": False, "how": "view"}, arg
        assert ref.record["inputs"][arg]["copied"] is False
    # strided: one copy each, reported, same bits
    rgba = np.concatenate([rgb, np.ones(rgb.shape[:2] + (1,), np.float32)], axis=2)
    wide = np.zeros((rng.shape[0], rng.shape[1] + 9), np.float32)
    wide[:, 4:-5] = rng
    r = call(rgba[..., :3], wide[:, 4:-5])
    seen = _brume._debug_last_inputs()
    for arg in inputs:
        assert seen[arg]["copied"] and seen[arg]["how"].startswith("copied: strided"), arg
        assert r.record["inputs"][arg]["copied"] is True
    for k, v in ref.__dict__.items():
        if isinstance(v, np.ndarray):
            same(r[k], v)
    if name == "sky.fit":
        assert r.fit == ref.fit


def test_other_layouts_are_converted_once():
    rgb = np.random.default_rng(2).random((40, 30, 3), dtype=np.float32)
    ref = brume.blur(rgb, sigma=2).rgb
    for arr in (rgb.astype(np.float64), np.asfortranarray(rgb), rgb[::-1][::-1]):
        same(brume.blur(arr, sigma=2).rgb, ref)
    brume.blur(rgb.astype(np.float64), sigma=2)
    assert _brume._debug_last_inputs()["rgb"]["copied"]


def test_uint8_with_transfer_equals_reading_the_png(demo, tmp_path):
    rgb8 = (np.arange(48 * 64 * 3) % 256).astype(np.uint8).reshape(48, 64, 3)
    brume.write_image(tmp_path / "x.png", rgb8.astype(np.float32) / 255, transfer="linear", bits="8")
    from_file = brume.read_image(tmp_path / "x.png").rgb  # integer file: sRGB, as the CLI reads it
    same(brume.blur(rgb8, sigma=1.0, transfer="srgb").rgb, brume.blur(from_file, sigma=1.0).rgb)
    lin = brume.blur(rgb8, sigma=1.0, transfer="linear").rgb
    same(lin, brume.blur(rgb8.astype(np.float32) * np.float32(1 / 255), sigma=1.0).rgb)


def test_read_image_takes_a_gamma_or_a_camera_response(tmp_path):
    # As the CLI's --image-transfer: each 8-bit code through code/255 ** G in
    # double, rounded once to float; a table's entries at the codes exactly.
    codes = (np.arange(16 * 16 * 3) % 256).astype(np.uint8).reshape(16, 16, 3)
    brume.write_image(tmp_path / "c.png", codes.astype(np.float32) / 255, transfer="linear", bits="8")
    got = brume.read_image(tmp_path / "c.png", transfer="gamma:2.2")
    assert got.file["transfer"] == "gamma:2.2"
    same(got.rgb, ((codes / 255.0) ** 2.2).astype(np.float32))
    table = (np.arange(256) / 255.0) ** 2.6
    (tmp_path / "t.txt").write_text("# response\n" + "\n".join(repr(float(v)) for v in table))
    got = brume.read_image(tmp_path / "c.png", transfer="table:" + str(tmp_path / "t.txt"))
    same(got.rgb, table[codes].astype(np.float32))
    with pytest.raises(ValueError, match=r"transfer= 'gamma:0'.*\(0, 10\]"):
        brume.read_image(tmp_path / "c.png", transfer="gamma:0")
    with pytest.raises(TypeError, match=r"transfer takes a str"):
        brume.read_image(tmp_path / "c.png", transfer=2.2)


# ---- errors -----------------------------------------------------------------------------------------
def test_unknown_keyword_names_the_nearest(demo):
    with pytest.raises(TypeError, match=r"visibilty.*did you mean: visibility"):
        brume.haze(demo["rgb"], demo["range"], visibilty=300)
    with pytest.raises(TypeError, match="f_number"):
        brume.dof(demo["rgb"], demo["range"], f_numbr=2)


def test_bad_types_and_ranges(demo):
    rgb, rng = demo["rgb"], demo["range"]
    with pytest.raises(ValueError, match=r"brume\.haze\(\): visibility=-5 is not allowed.*\(0, inf\)"):
        brume.haze(rgb, rng, visibility=-5)
    with pytest.raises(TypeError, match="keyword visibility takes a number"):
        brume.haze(rgb, rng, visibility="far")
    with pytest.raises(TypeError, match="keyword threads takes an int"):
        brume.haze(rgb, rng, threads=1.5)
    with pytest.raises(TypeError, match="keyword threads takes an int"):
        brume.haze(rgb, rng, threads=True)
    with pytest.raises(ValueError, match="scheme.*use one of"):
        brume.haze(rgb, rng, scheme="fast")
    with pytest.raises(TypeError, match="airlight takes a sequence of 3"):
        brume.haze(rgb, rng, airlight=(1, 2))
    with pytest.raises(ValueError, match="airlight"):
        brume.haze(rgb, rng, airlight=(1, -2, 0.5))
    with pytest.raises(TypeError, match="lambda_ given twice"):
        brume.haze(rgb, rng, lambda_=1, **{"lambda": 2})
    # a combination the run would ignore: the library's own message
    with pytest.raises(ValueError, match="albedo"):
        brume.haze(rgb, rng, albedo=0.5)
    with pytest.raises(ValueError, match="reference is the CPU's"):
        brume.haze(rgb, rng, reference=True, backend="gpu")


def test_bad_arrays_name_argument_shape_dtype(demo):
    rgb, rng = demo["rgb"], demo["range"]
    with pytest.raises(ValueError, match=r"rgb has shape \(112, 160\) and dtype float32.*H x W x 3"):
        brume.haze(rgb[..., 0], rng)
    with pytest.raises(ValueError, match=r"rgb has shape \(112, 160, 3\) and dtype int32"):
        brume.haze(rgb.astype(np.int32), rng)
    with pytest.raises(ValueError, match=r"uint8.*transfer='srgb'"):
        brume.haze((rgb * 255).astype(np.uint8), rng)
    with pytest.raises(ValueError, match=r"transfer='srgb' applies to uint8/uint16 rgb only"):
        brume.haze(rgb, rng, transfer="srgb")
    with pytest.raises(ValueError, match=r"range has shape \(112, 160, 3\)"):
        brume.haze(rgb, rgb)
    with pytest.raises(ValueError, match=r"range has shape .* uint16.*metres"):
        brume.haze(rgb, np.nan_to_num(rng).astype(np.uint16))
    with pytest.raises(TypeError, match="rgb must be a numpy.ndarray"):
        brume.haze(rgb.tolist(), rng)
    with pytest.raises(ValueError, match="the same size|does not match|size"):
        brume.haze(rgb, rng[:50])
    with pytest.raises(ValueError, match="sigma0"):
        brume.blur(rgb, sigma=0.5)
    with pytest.raises(ValueError, match="not both"):
        brume.blur(rgb, rng, sigma=2)


def test_file_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such file"):
        brume.read_image(tmp_path / "missing.png")
    with pytest.raises(FileNotFoundError, match="no such file"):
        brume.depth.convert(range=tmp_path / "missing.exr")
    with pytest.raises(ValueError, match="does not exist"):
        brume.write_image(tmp_path / "no" / "dir.png", np.zeros((4, 4, 3), np.float32))


def test_path_that_is_not_utf8_is_refused_by_name(tmp_path):
    # os.fsdecode of a file name that is not UTF-8 gives a str with lone
    # surrogates: brume's message, the bytes as \xHH, not pybind11's cast error.
    name = os.fsdecode(b"im\xff.png")
    with pytest.raises(ValueError, match=r"path '.*im\\xFF\.png' is not valid UTF-8"):
        brume.read_image(str(tmp_path / name))
    with pytest.raises(ValueError, match="is not valid UTF-8"):
        brume.write_image(tmp_path / name, np.zeros((4, 4, 3), np.float32))
    assert not any(tmp_path.iterdir())


def test_missing_gpu_is_a_runtime_error():
    # No EGL platform may be tried: the context cannot be made, whatever the machine.
    code = ("import numpy as np, brume\n"
            "try:\n    brume.blur(np.zeros((4,4,3),np.float32), sigma=2, backend='gpu')\n"
            "except RuntimeError as e:\n    print('RuntimeError', e)\n")
    env = dict(os.environ, BRUME_EGL_PLATFORM="none-such")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("RuntimeError brume.blur(): no OpenGL ES 3.2 context: no headless EGL platform "
                                 "(device or Mesa surfaceless); install Mesa"), out.stdout + out.stderr


# ---- the GIL, threads -------------------------------------------------------------------------------
def test_gil_is_released_during_a_long_blur():
    # (1000 x 1400: long enough to tell; 600 x 800 took 46 ms on one Zen 5 core
    # once the engine had got faster, under the 50 ms floor below.)
    rgb = np.random.default_rng(3).random((1000, 1400, 3), dtype=np.float32)
    assert_gil_released(lambda: brume.blur(rgb, sigma=20, threads=1), "blur")


def test_threads_give_identical_results(demo):
    rgb, rng = demo["rgb"], demo["range"]
    ref = brume.haze(rgb, rng, visibility=800, lambda_=10, threads=1)
    same(brume.haze(rgb, rng, visibility=800, lambda_=10, threads=2).rgb, ref.rgb)
    results = [None] * 4

    def work(i):
        results[i] = brume.haze(rgb, rng, visibility=800, lambda_=10, threads=1)

    ts = [threading.Thread(target=work, args=(i,)) for i in range(4)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    for r in results:
        same(r.rgb, ref.rgb)
        same(r.transmission, ref.transmission)


# ---- files --------------------------------------------------------------------------------------------
def test_read_write_round_trip(tmp_path):
    rgb = np.random.default_rng(4).random((30, 40, 3), dtype=np.float32) * 4
    brume.write_image(tmp_path / "x.exr", rgb, record={"note": "hello", "lambda": 3})
    back = brume.read_image(tmp_path / "x.exr")
    same(back.rgb, rgb)  # float EXR: exact
    assert back.record == {"note": "hello", "lambda": 3}
    assert back.file["format"] == "openexr"
    # 16-bit PNG: sRGB-encoded, within half a count of the encoded value
    small = np.clip(rgb / 4, 0, 1)
    brume.write_image(tmp_path / "x.png", small, bits="16")
    png = brume.read_image(tmp_path / "x.png")
    enc = lambda v: np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)
    assert np.max(np.abs(enc(png.rgb.astype(np.float64)) - enc(small.astype(np.float64)))) <= 0.5 / 65535 + 1e-6
    assert png.file["bits"] == 16 and png.record is None
    # a 2-D array is data: never sRGB-encoded
    m = np.linspace(0, 1, 30 * 40, dtype=np.float32).reshape(30, 40)
    brume.write_image(tmp_path / "m.png", m, bits="16")
    assert np.max(np.abs(brume.read_image(tmp_path / "m.png", "linear").rgb[..., 0] - m)) <= 0.5 / 65535 + 1e-7


def test_write_image_compression(tmp_path):
    # the CLI's --compression: stored deflate blocks hold the raw 8-bit samples, the pixels are the default's
    rgb = np.random.default_rng(5).random((32, 48, 3), dtype=np.float32)
    brume.write_image(tmp_path / "d.png", rgb, bits="8")
    brume.write_image(tmp_path / "n.png", rgb, bits="8", compression="none")
    assert (tmp_path / "n.png").stat().st_size >= 32 * 48 * 3
    same(brume.read_image(tmp_path / "n.png").rgb, brume.read_image(tmp_path / "d.png").rgb)
    with pytest.raises(ValueError, match=r"'lzw'.*\.png files take auto, none, zip"):
        brume.write_image(tmp_path / "x.png", rgb, compression="lzw")
    assert not (tmp_path / "x.png").exists()


def test_result_record_embeds_and_reads_back(demo, tmp_path):
    r = brume.haze(demo["rgb"], demo["range"], visibility=2000)
    brume.write_image(tmp_path / "h.png", r.rgb, record=r.record)
    back = brume.read_image(tmp_path / "h.png").record
    assert back["job"]["haze"]["visibility"] == 2000 and back["command"] == "haze"


# ---- documentation from the tables --------------------------------------------------------------
def test_help_and_stubs_come_from_the_tables():
    doc = brume.haze.__doc__
    assert "visibility = auto" in doc and "meteorological visibility" in doc
    assert "lambda_ = 15" in doc and "sigma0" in doc and "threads" in doc and "prepare" in doc
    assert "f_number" in brume.dof.__doc__ and "focus_distance" in brume.dof.__doc__
    stub = os.path.join(os.path.dirname(brume.__file__), "_brume.pyi")
    with open(stub, encoding="utf-8") as f:
        text = f.read()
    assert "def haze(rgb: npt.NDArray[Any], range: npt.NDArray[Any], *, transfer:" in text
    assert "lambda_: float = ..." in text
    assert 'scheme: Literal["standard", "invariant", "invariant-exact"]' in text or "scheme: Literal[" in text
    assert text == _brume._stub_text()
    import ast
    tree = ast.parse(text)  # the stubs are valid Python
    defs = {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert {"haze", "aerial", "fog", "dof", "blur", "depth_convert", "depth_prepare", "sky_render", "sky_fit"} <= set(defs)
    # every keyword the function accepts is in its stub, and no other
    hz = {a.arg for a in defs["haze"].args.kwonlyargs}
    assert "lambda_" in hz and "visibility" in hz and "threads" in hz and "transfer" in hz
    with pytest.raises(TypeError):
        brume.haze(np.zeros((2, 2, 3), np.float32), np.ones((2, 2), np.float32), not_a_stub_keyword=1)


# ---- GPU (llvmpipe where there is no hardware) ------------------------------------------------------
def test_gpu_haze_and_blur_match_cpu(demo, gpu):
    rgb, rng = demo["rgb"], demo["range"]
    cpu = brume.haze(rgb, rng, visibility=1500, lambda_=8)
    g = brume.haze(rgb, rng, visibility=1500, lambda_=8, backend="gpu")
    assert g.record["execution"]["backend"] == "gpu"
    assert math.sqrt(np.mean((g.rgb - cpu.rgb) ** 2)) < 1e-3  # f32 GPU arithmetic vs CPU (README: RMS <= 1e-3)
    gb = brume.blur(rgb, sigma=3, backend="gpu").rgb
    assert math.sqrt(np.mean((gb - brume.blur(rgb, sigma=3).rgb) ** 2)) < 1e-3


def test_gpu_rain_snow_wet_match_cpu(demo, gpu):
    """backend="gpu" on the camera effects of falling particles and wet ground: the record says
    which backend ran and what stayed on the CPU; the same particles; the image within the float
    bounds of tests/test_rain_gpu.cpp and tests/test_wet_gpu.cpp (per pixel 1e-5; the wet
    ground's mirrored rays may take the pixel beside the CPU's in a small share)."""
    rgb, rng = demo["rgb"], demo["range"]
    for fn, kw, block in ((brume.rain, dict(rate=25, z_split=5), "rain"), (brume.snow, dict(rate=1, z_split=5), "snow")):
        cpu = fn(rgb, rng, fov_y=55, prepare="off", **kw)
        g = fn(rgb, rng, fov_y=55, prepare="off", backend="gpu", **kw)
        assert g.record["execution"]["backend"] == "gpu" and cpu.record["execution"]["backend"] == "cpu"
        assert "on the CPU" in g.record["execution"]["split"]
        assert g.record[block] == cpu.record[block]
        assert np.max(np.abs(g.rgb - cpu.rgb)) < 1e-5 and np.max(np.abs(g.transmission - cpu.transmission)) < 1e-5
    pose = dict(fov_y=55, camera_height=1.6, pitch=-5)
    cpu = brume.wet(rgb, rng, film=1.5, **pose)
    g = brume.wet(rgb, rng, film=1.5, backend="gpu", **pose)
    assert g.record["execution"]["backend"] == "gpu" and "march" in g.record["execution"]
    assert np.array_equal(g.ground, cpu.ground)
    off = g.ground == 0
    assert np.array_equal(g.rgb[off], rgb[off])  # off the ground: the input, bit for bit
    far = np.max(np.abs(g.rgb - cpu.rgb), axis=-1) > 1e-5
    assert far.sum() <= 0.02 * cpu.ground.sum()
    # the march that ran, on both backends: the default above-ground, blocks when asked
    assert g.record["wet"]["mirror_march"] == cpu.record["wet"]["mirror_march"] == "above-ground"
    assert "mirror_march_because" not in g.record["wet"]
    gb = brume.wet(rgb, rng, film=1.5, backend="gpu", mirror_march="blocks", **pose)
    assert gb.record["wet"]["mirror_march"] == "blocks" and np.array_equal(gb.rgb[off], rgb[off])


def test_gpu_from_threads(demo, gpu):
    """Each thread makes its own context on its first GPU call and reuses it
    for its later ones (the same context, the same bits); two threads hold two
    contexts, run concurrently and agree bit for bit; a CPU call makes none."""
    rgb = demo["rgb"]
    out = [None, None, None]
    ctx = [None, None]
    both_alive = threading.Barrier(2, timeout=120)  # both contexts exist at once: distinct addresses mean distinct

    def work(i):
        assert _brume._debug_thread_gpu() is None  # a fresh thread has no context yet
        brume.blur(rgb, sigma=2)  # the CPU backend makes none
        assert _brume._debug_thread_gpu() is None
        out[i] = brume.blur(rgb, sigma=3, backend="gpu").rgb
        ctx[i] = _brume._debug_thread_gpu()
        again = brume.haze(rgb, demo["range"], visibility=1500, backend="gpu")
        assert _brume._debug_thread_gpu() == ctx[i]  # reused, not remade
        assert again.record["execution"]["backend"] == "gpu"
        if i == 0:
            out[2] = brume.blur(rgb, sigma=3, backend="gpu").rgb
        both_alive.wait()

    ts = [threading.Thread(target=work, args=(i,)) for i in range(2)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    assert ctx[0] is not None and ctx[1] is not None and ctx[0] != ctx[1]
    assert out[0] is not None and np.array_equal(out[0], out[1]) and np.array_equal(out[0], out[2])


# ---- aerial's turbidity from a sky fit (issue #14 item: as `brume aerial` has it) -------------
def _without_timing(fit):
    return {k: v for k, v in fit.items() if k != "fit_ms"}


def _same_job_blocks(py, cli):
    """The Python record's job blocks equal the CLI's; its depth block holds
    only the array form's keywords (the intrinsics, for path='slant'), each
    with the CLI's value."""
    for block in py:
        if block == "depth":
            assert {k: cli[block][k] for k in py[block]} == py[block]
        else:
            assert py[block] == cli[block], block


def test_aerial_turbidity_from_sky_fit_equals_cli(demo, tmp_path):
    """turbidity_from= (a `brume sky fit` JSON) and turbidity='auto' with
    sky_image= (the fit run on the photo) give the CLI's pixels bit for bit,
    the same turbidity and the same record blocks; the fit recovers the
    rendered T = 5 (a noise-free Preetham sky: within 0.05, as the sky.fit test)."""
    d = demo["dir"]
    sky, fit = tmp_path / "sky.exr", tmp_path / "fit.json"
    run_cli("sky", "render", "--turbidity", 5, "--sun-zenith", 40, "--sun-azimuth", 120, "--width", 96,
            "--height", 48, "--out", sky)
    run_cli("sky", "fit", "--image", sky, "--sun-zenith", 40, "--sun-azimuth", 120, "--out", fit)
    common = ["--image", d / "clean.png", "--range", d / "range.exr", "--lambda", 3, "--bits", "float"]

    run_cli("aerial", *common, "--turbidity-from", fit, "--out", tmp_path / "a.exr")
    cli = brume.read_image(tmp_path / "a.exr")
    r = brume.aerial(demo["rgb"], demo["range"], turbidity_from=fit, lambda_=3)
    same(r.rgb, cli.rgb)
    assert r.record["aerial"] == cli.record["aerial"]
    _same_job_blocks(r.record["job"], cli.record["job"])
    assert abs(r.record["job"]["aerial"]["turbidity"] - 5) < 0.05

    run_cli("aerial", *common, "--turbidity", "auto", "--sky-image", sky, "--sky-sun-zenith", 40,
            "--sky-sun-azimuth", 120, "--out", tmp_path / "b.exr")
    cli = brume.read_image(tmp_path / "b.exr")
    r = brume.aerial(demo["rgb"], demo["range"], turbidity="auto", sky_image=sky, sky_sun_zenith=40,
                     sky_sun_azimuth=120, lambda_=3)
    same(r.rgb, cli.rgb)
    assert _without_timing(r.record["turbidity_fit"]) == _without_timing(cli.record["turbidity_fit"])
    assert r.record["inputs"]["sky_image"] == cli.record["inputs"]["sky_image"]
    assert r.record["aerial"] == cli.record["aerial"]
    _same_job_blocks(r.record["job"], cli.record["job"])
    assert r.record["job"]["aerial"]["turbidity"] == "auto" or r.record["job"]["aerial"]["turbidity"] is None
    assert abs(r.record["turbidity_fit"]["turbidity"] - 5) < 0.05


def test_aerial_sky_arguments_are_checked_as_the_cli(demo, tmp_path):
    rgb, rng = demo["rgb"], demo["range"]
    with pytest.raises(ValueError, match="sky_image"):  # a sky flag without the photo
        brume.aerial(rgb, rng, turbidity=3, sky_sun_zenith=40)
    with pytest.raises(ValueError, match="is for turbidity='auto'"):  # a photo with a given T
        brume.aerial(rgb, rng, turbidity=3, sky_image=tmp_path / "none.exr")
    with pytest.raises(FileNotFoundError):
        brume.aerial(rgb, rng, turbidity_from=tmp_path / "missing.json")


# ---- the --max-pixels limit (process-wide, as the CLI's root option) ---------------------------
def test_max_pixels_limits_every_file_read(demo, tmp_path):
    """brume.set_max_pixels is the CLI's --max-pixels: a file declaring more
    pixels is refused before its pixels are read, by read_image and by the
    other readers (depth.convert); arrays are not limited; the message names
    the Python fix. 160 x 112 = 17920 pixels: a limit one below refuses it."""
    d = demo["dir"]
    assert brume.max_pixels() == 500_000_000  # the CLI's default
    try:
        brume.set_max_pixels(160 * 112)
        assert brume.read_image(d / "clean.png").rgb.shape == (112, 160, 3)  # exactly at the limit: read
        brume.set_max_pixels(160 * 112 - 1)
        assert brume.max_pixels() == 17919
        with pytest.raises(ValueError, match=r"over the limit.*brume\.set_max_pixels"):
            brume.read_image(d / "clean.png")
        with pytest.raises(ValueError, match="over the limit"):
            brume.depth.convert(range=d / "range.exr")
        brume.blur(demo["rgb"], sigma=2)  # an array is not a file: no limit
        # the same limit as the CLI's flag
        r = subprocess.run([str(x) for x in [cli_path(), "--max-pixels", 17919, "blur", "--image", d / "clean.png",
                                             "--sigma", 2, "--out", tmp_path / "o.exr"]], capture_output=True, text=True)
        assert r.returncode != 0 and "over the limit" in r.stderr
    finally:
        brume.set_max_pixels(500_000_000)
    with pytest.raises(ValueError, match="1 .. 1e12"):
        brume.set_max_pixels(0)
    with pytest.raises(TypeError, match="int"):
        brume.set_max_pixels(1e6)
    with pytest.raises(TypeError, match="int"):
        brume.set_max_pixels(True)
    assert brume.max_pixels() == 500_000_000


# ---- replaying a record: job= and brume.rerun ---------------------------------------------------
def test_haze_record_replays_bit_for_bit(demo, tmp_path):
    """A haze record holds both visibility and the default kappa-a; spreading
    it as keywords is refused by the given rule (as on the command line), but
    job= (and brume.rerun) read it as `brume run` does and reproduce the run
    bit for bit -- from the Python record and from the CLI's."""
    rgb, rng = demo["rgb"], demo["range"]
    r = brume.haze(rgb, rng, visibility=3000, albedo=0.9, lambda_=6, threads=2)
    assert "kappa-a" in r.record["job"]["haze"] and r.record["job"]["haze"]["visibility"] == 3000
    with pytest.raises(ValueError, match="visibility"):  # the trap, still a clear error
        brume.haze(rgb, rng, **r.record["job"]["haze"])
    for again in (brume.haze(rgb, rng, job=r.record["job"]), brume.rerun(r.record, rgb, rng, threads=1)):
        same(again.rgb, r.rgb)
        same(again.transmission, r.transmission)
        assert again.record["job"] == r.record["job"]
    # a CLI record: its input/output blocks name files (the arrays replace them)
    d = demo["dir"]
    run_cli("haze", "--image", d / "clean.png", "--range", d / "range.exr", "--visibility", 700, "--lambda", 3,
            "--sky-margin", 5, "--out", tmp_path / "o.exr", "--bits", "float")
    cli = brume.read_image(tmp_path / "o.exr")
    same(brume.rerun(cli.record, rgb, rng).rgb, cli.rgb)
    # keywords override the job's values (and count as given)
    same(brume.haze(rgb, rng, job=r.record["job"], lambda_=3).rgb,
         brume.haze(rgb, rng, visibility=3000, albedo=0.9, lambda_=3).rgb)


def test_rerun_other_effects_and_bad_records(demo):
    rgb, rng = demo["rgb"], demo["range"]
    for r in (brume.fog(rgb, rng, fov_y=55, camera_height=1.6, density=0.03, lambda_=2),
              brume.dof(rgb, rng, focus_distance=3.9, coc_infinity=6, fov_y=55),
              brume.aerial(rgb, rng, turbidity=4, lambda_=2)):
        same(brume.rerun(r.record, rgb, rng).rgb, r.rgb)
    with pytest.raises(ValueError, match="not a brume parameter record"):
        brume.rerun({"job": {}}, rgb, rng)
    with pytest.raises(ValueError, match="not one of"):
        brume.rerun(brume.blur(rgb, sigma=2).record, rgb, rng)
    with pytest.raises(ValueError, match="'haze.bogus' is not a parameter"):
        brume.haze(rgb, rng, job={"haze": {"bogus": 1}})
    with pytest.raises(ValueError, match="visibility"):
        brume.haze(rgb, rng, job={"haze": {"visibility": -5}})
    with pytest.raises(TypeError, match="job"):
        brume.haze(rgb, rng, job="haze")


def test_rerun_of_an_older_schema_keeps_its_sky_rule(demo):
    """A schema-2 record (its job without sky-rule) replays under the rule it
    ran under, the sky at S_max, as `brume run` replays it: bit for bit the
    run with sky_rule="s-max", not the new rule's airlight sky."""
    rgb, rng = demo["rgb"], demo["range"]
    new = brume.haze(rgb, rng, visibility=300, lambda_=0)
    old = brume.haze(rgb, rng, visibility=300, lambda_=0, sky_rule="s-max")
    assert not np.array_equal(new.rgb, old.rgb)  # the demo scene has sky
    v2 = dict(new.record, schema_version=2, job={k: dict(v) for k, v in new.record["job"].items()})
    del v2["job"]["haze"]["sky-rule"]
    same(brume.rerun(v2, rgb, rng).rgb, old.rgb)
    same(brume.rerun(new.record, rgb, rng).rgb, new.rgb)


# ---- the library's list of commands (brume/command.hpp) reaches Python -------------------
CAMERA = {"fog": {"fov_y": 55, "camera_height": 1.6}, "dof": {"fov_x": 2 * math.degrees(math.atan(18 / 50))},
          "rain": {"fov_y": 55},  # the drops are placed by the intrinsics
          "wet": {"fov_y": 55, "camera_height": 1.6, "pitch": -5},  # the ground plane
          "snow": {"fov_y": 55},  # the flakes too
          # the chain samples per stage (brume.transforms); here a fixed lens after haze's defaults
          "haze+dof": {"visibility": 2000, "dof_focus_distance": 20, "dof_coc_infinity": 4, "fov_x": 40}}


def test_every_command_of_the_list_reaches_python(demo):
    """Each command with an array form is a function of the module, with its
    positional arrays in its stub; those on (rgb, range) run on the demo's
    arrays, record their command, and are repeated by brume.rerun bit for bit;
    each sampleable one draws through random_params; the stubs list every
    function and the sampleable effects."""
    commands = _brume._commands()
    names = [c["name"] for c in commands]
    assert len(names) == len(set(names)) and "haze" in names
    stubs = _brume._stub_text()
    rgb, rng = demo["rgb"][::4, ::4], demo["range"][::4, ::4]
    forms = [c for c in commands if c["function"]]
    assert {"haze", "aerial", "fog", "dof", "blur", "depth convert", "depth prepare", "sky render",
            "sky fit"} <= {c["name"] for c in forms}
    for c in commands:
        if c["sample"]:
            assert brume.random_params(c["name"], 7, "frame/1")
            assert f"'{c['name']}'" in stubs.split("def random_params(")[1].split(")")[0]
    for c in forms:
        stub = stubs.split(f"def {c['function']}(")[1].split(")")[0]
        assert [a.split(":")[0].strip() for a in stub.split(", ") if "NDArray" in a] == c["arrays"] + c["keyword_arrays"]
        public = brume
        for part in c["public_name"].split(".")[1:]:
            public = getattr(public, part)
        assert public is getattr(_brume, c["function"])
        if c["arrays"] != ["rgb", "range"]:
            continue
        assert c["replays"]
        # Its sampled parameters, with the camera the fog's heights and the lens's planar depth need.
        kw = brume.random_params(c["name"], 7, "frame/1") if c["sample"] else {}
        kw.update(CAMERA.get(c["name"], {}))
        r = public(rgb, rng, threads=1, **kw)
        assert r.record["command"] == c["name"]
        again = brume.rerun(r.record, rgb, rng, threads=1)
        arrays = [k for k, v in r.__dict__.items() if isinstance(v, np.ndarray)]  # rgb; depth complete: range, ...
        assert arrays
        for k in arrays:
            same(getattr(again, k), getattr(r, k))


def test_record_warnings_are_python_warnings():
    """What the record warns of is a UserWarning in Python's words (the CLI
    prints it on stderr): here the preparation's sky under a measured surface
    -- the top quarter's range unknown, joined by a column to unknown range
    beneath a "table" of known range -- whose remedy the warning names as
    complete='on'. The top quarter alone warns nothing; the record keeps the
    warning either way."""
    import warnings
    h, w = 48, 64
    rgb = np.full((h, w, 3), 0.3, np.float32)
    rng = np.full((h, w), 10.0, np.float32)
    rng[:12] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plain = brume.haze(rgb, rng, visibility=100)
    assert "warnings" not in plain.record["prepare"]["complete"]
    assert plain.record["prepare"]["complete"]["prepared_sky_under_surface_fraction"] == 0.0
    rng[16:26, 10:50] = np.nan   # beneath the table (rows 12-15 stay known)
    rng[12:17, 5] = np.nan       # the joint to the sky
    rng[16, 5:10] = np.nan
    with pytest.warns(UserWarning, match=r"brume\.haze\(\): the range's unknown regions .* give complete='on'"):
        r = brume.haze(rgb, rng, visibility=100)
    assert r.record["prepare"]["complete"]["warnings"]
    assert r.record["prepare"]["complete"]["prepared_sky_under_surface_fraction"] == pytest.approx(404 / (h * w))
