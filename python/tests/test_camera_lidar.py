"""A camera frame and its LiDAR scan from one medium, in Python: the array
forms' lidar= (brume.haze, fog, aerial, haze_dof) against the CLI's
--lidar/--lidar-out bit for bit, one medium for both, replay and `brume run`
of the record, bad input; the camera transforms' lidar_target (one draw for
the image and the scan, replay, `brume run`, p=0)."""
import json
import subprocess

import numpy as np
import pytest

import brume
import brume.transforms as T
from brume import _brume
from conftest import cli_path, require_data, run_cli, scan


def read_bin(path):
    return np.fromfile(path, dtype=np.float32).reshape(-1, 4)


# Each camera effect with a medium: its Python keywords and the same as flags
# (the subcommand first); a quick run on the demo scene.
CASES = {
    "haze": (brume.haze, dict(visibility=60.0, lambda_=1.0), ["haze", "--visibility", 60, "--lambda", 1]),
    "fog": (brume.fog, dict(profile="constant", density=0.06, fov_y=55.0),
            ["fog", "--profile", "constant", "--density", 0.06, "--fov-y", 55]),
    "aerial": (brume.aerial, dict(turbidity=8.0, distance_scale=1000.0, lidar_wavelength=1550.0),
               ["aerial", "--turbidity", 8, "--distance-scale", 1000, "--lidar-wavelength", 1550]),
    "haze+dof": (brume.haze_dof, dict(visibility=70.0, dof_focus_distance=20.0, dof_coc_infinity=4.0, fov_x=40.0),
                 ["haze", "--visibility", 70, "--dof-focus-distance", 20, "--dof-coc-infinity", 4, "--fov-x", 40]),
}


@pytest.mark.parametrize("name", list(CASES))
def test_array_forms_fog_the_scan_as_the_cli(demo, tmp_path, name):
    """brume.<effect>(rgb, range, lidar=points) returns the scan the CLI's
    --lidar-out writes on the same inputs, bit for bit, with the same record
    block and job settings; the scan is read in place; the image is the one
    the call without a scan gives (the scan changes no pixel)."""
    f, kw, flags = CASES[name]
    pts = scan()
    pts.tofile(tmp_path / "in.bin")
    d = demo["dir"]
    run_cli(*flags, "--image", d / "clean.png", "--range", d / "range.exr", "--lidar", tmp_path / "in.bin",
            "--lidar-out", tmp_path / "s.bin", "--lidar-seed", 11,
            "--out", tmp_path / "o.png", "--record", tmp_path / "o.json")
    cli = json.loads((tmp_path / "o.json").read_text())
    r = f(demo["rgb"], demo["range"], lidar=pts, lidar_seed=11, threads=1, **kw)
    assert r.lidar.shape == pts.shape and r.lidar.dtype == np.float32
    assert np.array_equal(r.lidar, read_bin(tmp_path / "s.bin"))
    assert r["lidar"] is r.lidar
    timing = lambda b: {k: v for k, v in b.items() if not k.endswith("_ms")}  # (the run's own timings)
    assert timing(r.record["lidar"]) == timing(cli["lidar"])  # alpha, its rule, the model's parameters, the figures
    assert r.record["lidar"]["soft_points"] > 0
    files = {"lidar", "lidar-out"}
    assert r.record["job"]["lidar"] == {k: v for k, v in cli["job"]["lidar"].items() if k not in files}
    assert r.record["inputs"]["lidar"] == {"source": "numpy", "shape": [len(pts), 4], "dtype": "float32",
                                           "copied": False, "points": len(pts)}
    assert _brume._debug_last_inputs()["lidar"]["copied"] is False
    plain = f(demo["rgb"], demo["range"], threads=1, **{k: v for k, v in kw.items() if not k.startswith("lidar")})
    assert np.array_equal(r.rgb, plain.rgb)
    assert plain.lidar is None and "lidar" not in plain.record and "lidar" not in plain.record["job"]


def test_one_medium_for_the_image_and_the_scan(demo):
    """Haze with visibility V: the scan's alpha is the image's extinction
    3.912/V (the same double), and every point that stays in place is
    attenuated by exp(-2 alpha R), checked in double precision here."""
    pts = scan()
    v = 80.0
    r = brume.haze(demo["rgb"], demo["range"], visibility=v, lidar=pts)
    alpha = r.record["lidar"]["alpha_per_m"]
    assert alpha == 3.912 / v == r.record["haze"]["derived"]["extinction_per_m"]
    assert r.record["lidar"]["alpha_from"].startswith("the camera's extinction")
    kept = np.all(r.lidar[:, :3] == pts[:, :3], axis=1)
    assert kept.sum() > 100 and (~kept).sum() > 100
    p = pts[kept].astype(np.float64)
    hard = p[:, 3] * np.exp(-2.0 * alpha * np.linalg.norm(p[:, :3], axis=1))
    # float32 output (half an ulp, 6e-8) of a range computed from float32 coordinates
    np.testing.assert_allclose(r.lidar[kept, 3], hard, rtol=2e-6, atol=0)
    # the same scan as brume.lidar.fog with that alpha (one function behind both)
    assert np.array_equal(r.lidar, brume.lidar.fog(pts, alpha=alpha).points)
    # aerial: the spectral medium at the LiDAR's wavelength (clearer at 1550 nm than at 905 nm)
    a905 = brume.aerial(demo["rgb"], demo["range"], turbidity=8.0, lidar=pts).record["lidar"]
    a1550 = brume.aerial(demo["rgb"], demo["range"], turbidity=8.0, lidar=pts, lidar_wavelength=1550.0)
    assert a905["wavelength_nm"] == 905.0 and 0 < a1550.record["lidar"]["alpha_per_m"] < a905["alpha_per_m"]


# A KITTI-like calibration (made up: a camera 2 6 cm left of a Velodyne 8 cm
# above it, looking along its x axis; R0_rect the identity).
CALIB = """P2: 720 0 320 43.2 0 720 240 0.2 0 0 1 0.003
R0_rect: 1 0 0 0 1 0 0 0 1
Tr_velo_to_cam: 0 -1 0 0 0 0 -1 -0.08 1 0 0 -0.27
"""


def test_fog_with_a_height_profile_places_the_scan_by_kitti_calib(demo, tmp_path):
    """brume.fog(..., profile exponential, lidar=, kitti_calib=): the scan
    through the fog's profile along each beam, placed by the calibration and
    the camera's pose: equal to `brume fog --kitti-calib ... --lidar` bit for
    bit; the record's job holds the file as the CLI's does and its inputs
    hash it; kitti_calib without a scan, or with a medium the same at every
    height, is refused; a CLI fog record that read a --kitti-calib for its
    depth (not for a scan) still replays without one."""
    (tmp_path / "calib.txt").write_text(CALIB)
    pts = scan()
    pts.tofile(tmp_path / "in.bin")
    d = demo["dir"]
    fog = dict(density=0.05, falloff=0.1, camera_height=1.65, pitch=2.0, fov_y=55.0)
    run_cli("fog", "--image", d / "clean.png", "--range", d / "range.exr", "--fov-y", 55, "--density", 0.05,
            "--falloff", 0.1, "--camera-height", 1.65, "--pitch", 2, "--kitti-calib", tmp_path / "calib.txt",
            "--lidar", tmp_path / "in.bin", "--lidar-out", tmp_path / "s.bin", "--lidar-seed", 2,
            "--out", tmp_path / "o.png", "--record", tmp_path / "o.json")
    cli = json.loads((tmp_path / "o.json").read_text())
    r = brume.fog(demo["rgb"], demo["range"], lidar=pts, kitti_calib=tmp_path / "calib.txt", lidar_seed=2, **fog)
    assert np.array_equal(r.lidar, read_bin(tmp_path / "s.bin"))
    timing = lambda b: {k: v for k, v in b.items() if not k.endswith("_ms")}
    assert timing(r.record["lidar"]) == timing(cli["lidar"])
    assert r.record["lidar"]["alpha_per_m"] is None and r.record["lidar"]["profile"] == "exponential"
    assert 0 < r.record["lidar"]["soft_points"] < len(pts)
    assert r.record["job"]["depth"]["kitti-calib"] == str(tmp_path / "calib.txt")
    assert r.record["inputs"]["kitti_calib"]["path"] == str(tmp_path / "calib.txt")
    assert len(r.record["inputs"]["kitti_calib"]["sha256"]) == 64
    plain = brume.fog(demo["rgb"], demo["range"], **fog)
    assert np.array_equal(r.rgb, plain.rgb) and "kitti-calib" not in plain.record["job"]["depth"]
    again = brume.fog(demo["rgb"], demo["range"], job=json.loads(json.dumps(r.record["job"])), lidar=pts)
    assert np.array_equal(again.lidar, r.lidar)
    with pytest.raises(ValueError, match="kitti_calib places the LiDAR scan.*no lidar= scan"):
        brume.fog(demo["rgb"], demo["range"], kitti_calib=tmp_path / "calib.txt", **fog)
    with pytest.raises(ValueError, match="kitti_calib places the scan in a fog that varies with height"):
        brume.fog(demo["rgb"], demo["range"], lidar=pts, kitti_calib=tmp_path / "calib.txt", profile="constant",
                  density=0.05, fov_y=55.0)
    # a CLI record whose depth block names a calibration (its depth source's) and no scan
    cli["job"]["lidar"].update({"lidar": "", "lidar-out": ""})
    same = brume.fog(demo["rgb"], demo["range"], job=cli["job"])
    assert same.lidar is None and np.array_equal(same.rgb, plain.rgb)


def test_kitti_frame_equals_the_cli(data_dir, tmp_path):
    """KITTI object 000001 (image_2, velodyne, calib): the camera's range
    from the scan, haze at 80 m; Python's scan equals the CLI's --lidar-out."""
    k = data_dir / "kitti_object_000001"
    require_data(k / "velodyne" / "000001.bin")
    img, velo, calib = k / "image_2" / "000001.png", k / "velodyne" / "000001.bin", k / "calib" / "000001.txt"
    run_cli("haze", "--image", img, "--velodyne", velo, "--kitti-calib", calib, "--visibility", 80,
            "--lidar", velo, "--lidar-out", tmp_path / "s.bin", "--out", tmp_path / "o.png")
    pts = np.fromfile(velo, np.float32).reshape(-1, 4)
    rgb = brume.read_image(img).rgb
    rng = brume.depth.convert(velodyne=velo, kitti_calib=calib, like=img).range
    r = brume.haze(rgb, rng, visibility=80.0, lidar=pts)
    assert np.array_equal(r.lidar, read_bin(tmp_path / "s.bin"))
    assert r.record["lidar"]["points"] == len(pts) == 120268 and r.record["lidar"]["soft_points"] > 0


def test_replay_rerun_and_brume_run_of_the_record(demo, tmp_path):
    """A record with a scan replays with job= and lidar= (and brume.rerun),
    bit for bit; without lidar= it is refused; a CLI record that fogged a
    scan replays with the scan as lidar=; `brume run` of the Python record's
    job (in a CLI record of the same pixels and scan as files) writes the
    same scan and image; a mistyped scan setting in a job is refused."""
    pts = scan()
    rgb, rng = demo["rgb"], demo["range"]
    r = brume.haze(rgb, rng, visibility=250.0, lidar=pts, lidar_seed=4)
    job = json.loads(json.dumps(r.record["job"]))
    again = brume.haze(rgb, rng, job=job, lidar=pts)
    assert np.array_equal(again.lidar, r.lidar) and np.array_equal(again.rgb, r.rgb)
    assert np.array_equal(brume.rerun(r.record, rgb, rng, lidar=pts).lidar, r.lidar)
    with pytest.raises(ValueError, match="lidar="):
        brume.haze(rgb, rng, job=job)
    # `brume run` of the Python record itself: its inputs were arrays, which it says (exit 2, nothing written)
    (tmp_path / "py.json").write_text(json.dumps(r.record))
    p = subprocess.run([cli_path(), "run", str(tmp_path / "py.json")], capture_output=True, text=True)
    assert p.returncode == 2 and "inputs (lidar, range, rgb) were numpy arrays" in p.stderr
    # the record through the CLI: float files of the same pixels and the scan's .bin
    brume.write_image(tmp_path / "rgb.pfm", rgb, bits="float")
    brume.write_image(tmp_path / "range.pfm", rng, bits="float", data=True)
    pts.tofile(tmp_path / "in.bin")
    run_cli("haze", "--image", tmp_path / "rgb.pfm", "--range", tmp_path / "range.pfm", "--out", tmp_path / "t.pfm",
            "--bits", "float", "--visibility", 100, "--lidar", tmp_path / "in.bin", "--lidar-out", tmp_path / "t.bin",
            "--record", tmp_path / "template.json")
    cli = json.loads((tmp_path / "template.json").read_text())
    for block, values in job.items():
        cli["job"].setdefault(block, {}).update(values)
    cli["job"]["output"].update({"out": str(tmp_path / "r.pfm"), "record": ""})
    cli["job"]["lidar"]["lidar-out"] = str(tmp_path / "r.bin")
    (tmp_path / "rec.json").write_text(json.dumps(cli))
    run_cli("run", tmp_path / "rec.json")
    assert np.array_equal(read_bin(tmp_path / "r.bin"), r.lidar)
    assert np.array_equal(brume.read_image(tmp_path / "r.pfm").rgb, r.rgb)
    # a CLI record that fogged a scan: its job with the scan as lidar=
    back = brume.haze(rgb, rng, job=cli["job"], lidar=pts)
    assert np.array_equal(back.lidar, r.lidar)
    # a hand-edited job's mistyped scan setting is refused, not passed over as the CLI's files are
    typo = json.loads(json.dumps(cli["job"]))
    typo["lidar"]["lidar-gamam"] = 1e-5
    with pytest.raises(ValueError, match="'lidar.lidar-gamam' is not a parameter of brume.haze"):
        brume.haze(rgb, rng, job=typo, lidar=pts)
    # a CLI record without a scan (its lidar block names no file) replays as before, without one
    run_cli("haze", "--image", tmp_path / "rgb.pfm", "--range", tmp_path / "range.pfm", "--out", tmp_path / "n.pfm",
            "--bits", "float", "--visibility", 250, "--record", tmp_path / "n.json")
    n = json.loads((tmp_path / "n.json").read_text())
    plain = brume.haze(rgb, rng, job=n["job"])
    assert plain.lidar is None and np.array_equal(plain.rgb, brume.read_image(tmp_path / "n.pfm").rgb)


def test_bad_input_names_the_keyword(demo):
    rgb, rng = demo["rgb"], demo["range"]
    pts = scan(200)
    with pytest.raises(ValueError, match=r"lidar has shape \(200, 3\).*\(N, 4\)"):
        brume.haze(rgb, rng, visibility=300.0, lidar=pts[:, :3])
    with pytest.raises(ValueError, match=r"lidar has shape \(200, 4\) and dtype int32: not float32"):
        brume.haze(rgb, rng, visibility=300.0, lidar=pts.astype(np.int32))
    with pytest.raises(ValueError, match=r"lidar has shape \(800,\)"):
        brume.haze(rgb, rng, visibility=300.0, lidar=pts.ravel())
    with pytest.raises(TypeError, match="lidar must be a numpy.ndarray"):
        brume.haze(rgb, rng, visibility=300.0, lidar=pts.tolist())
    with pytest.raises(ValueError, match="lidar_seed.*no lidar= scan"):
        brume.haze(rgb, rng, visibility=300.0, lidar_seed=3)
    with pytest.raises(ValueError, match="no physical extinction.*visibility"):
        brume.haze(rgb, rng, lidar=pts)  # normalised kappas: no metres for the scan
    with pytest.raises(ValueError, match="lidar_wavelength: the medium of haze is grey"):
        brume.haze(rgb, rng, visibility=300.0, lidar=pts, lidar_wavelength=1550.0)
    with pytest.raises(ValueError, match="varies with height.*give kitti_calib=FILE"):
        brume.fog(rgb, rng, fov_y=55.0, camera_height=1.6, density=0.03, lidar=pts)  # exponential
    with pytest.raises(ValueError, match="lidar.*lidar_intensity_scale=1"):
        brume.haze(rgb, rng, visibility=300.0, lidar=pts * np.float32([1, 1, 1, 255]))
    with pytest.raises(TypeError, match="unexpected keyword argument 'lidar_out'"):
        brume.haze(rgb, rng, visibility=300.0, lidar=pts, lidar_out="x.bin")
    with pytest.raises(TypeError, match="unexpected keyword argument 'lidar'"):
        brume.dof(rgb, rng, focus_distance=4.0, fov_y=55.0, lidar=pts)
    # float64 is converted once (and recorded so), a strided float32 array read where it lies: the same scan
    ref = brume.haze(rgb, rng, visibility=300.0, lidar=pts).lidar
    r64 = brume.haze(rgb, rng, visibility=300.0, lidar=pts.astype(np.float64))
    assert np.array_equal(r64.lidar, ref) and r64.record["inputs"]["lidar"]["copied"] is True
    wide = np.zeros((len(pts), 6), np.float32)
    wide[:, 1:5] = pts
    assert np.array_equal(brume.haze(rgb, rng, visibility=300.0, lidar=wide[:, 1:5]).lidar, ref)


def test_stub_and_docstring_name_the_scan():
    stub = _brume._stub_text().split("def haze(")[1].split(")")[0]
    assert "lidar: npt.NDArray[np.float32] | None" in stub and "lidar_seed:" in stub
    assert "lidar_out" not in stub
    assert "lidar=" in brume.haze.__doc__
    haze = {c["name"]: c for c in _brume._commands()}["haze"]
    assert haze["arrays"] == ["rgb", "range"] and haze["keyword_arrays"] == ["lidar"]


# ---- the transforms: one draw for the image and its scan --------------------------------------
def _scene(h=48, w=64, seed=0):
    g = np.random.default_rng(seed)
    rgb = g.random((h, w, 3), dtype=np.float32)
    yy, xx = np.mgrid[0:h, 0:w]
    return rgb, (20.0 + 3.0 * xx + 0.5 * yy).astype(np.float32)


def test_transform_fogs_image_and_scan_from_one_draw():
    """lidar_target="points": the scan is fogged with the draw's visibility
    (alpha 3.912/V, the image's extinction), its noise seed drawn per key;
    image and scan equal brume.haze with the drawn values and lidar=; other
    targets pass through; p=0 passes the image and the scan through as the
    same objects."""
    rgb, rng = _scene()
    pts = scan(3000)
    t = T.Haze(visibility=(150, 600), seed=3, lidar_target="points")
    out = t(image=rgb, depth=rng, points=pts, key="000001", label=7)
    assert set(out) == {"image", "depth", "points", "params", "label"} and out["label"] == 7
    v = out["params"]["values"]
    rec = out["params"]["record"]
    assert 150 <= v["visibility"] < 600 and isinstance(v["lidar-seed"], int)
    assert rec["lidar"]["alpha_per_m"] == 3.912 / v["visibility"] == rec["haze"]["derived"]["extinction_per_m"]
    assert rec["job"]["lidar"]["lidar-seed"] == v["lidar-seed"]
    direct = brume.haze(rgb, rng, lidar=pts, **v)
    assert np.array_equal(out["image"], direct.rgb) and np.array_equal(out["points"], direct.lidar)
    assert out["points"].dtype == np.float32 and not np.array_equal(out["points"], pts)
    # the image is the one the transform gives without a scan (same seed and key: the same draw)
    alone = T.Haze(visibility=(150, 600), seed=3)(image=rgb, depth=rng, key="000001")
    assert np.array_equal(alone["image"], out["image"])
    assert T.Haze(visibility=(150, 600), seed=3, lidar_target="points")(
        image=rgb, depth=rng, points=pts, key="000002")["params"]["values"]["lidar-seed"] != v["lidar-seed"]
    off = T.Haze(p=0.0, lidar_target="points")(image=rgb, depth=rng, points=pts, key="k")
    assert off["image"] is rgb and off["points"] is pts and off["params"]["record"] is None
    # a fixed noise seed is the user's
    fixed = T.Haze(visibility=300, lidar_seed=5, lidar_target="points")(image=rgb, depth=rng, points=pts, key="k")
    assert fixed["params"]["record"]["job"]["lidar"]["lidar-seed"] == 5
    # without lidar_target every target passes through untouched (the LidarFog transform's scan too)
    plain = T.Haze(visibility=300)(image=rgb, depth=rng, points=pts, key="k")
    assert plain["points"] is pts


def test_transform_replay_and_brume_run(tmp_path):
    """replay repeats image and scan bit for bit (another object, after a
    JSON round trip); `brume run` of the record (its job in a CLI record of
    the same pixels and scan) writes the same scan and image; a clip fogs
    each frame's scan with the clip's draw."""
    rgb, rng = _scene()
    pts = scan(3000)
    out = T.Fog(density=(0.03, 0.08), profile="constant", fov_y=50, seed=2,
                lidar_target="velodyne")(image=rgb, depth=rng, velodyne=pts, key="f/1")
    params = json.loads(json.dumps(out["params"]))
    # (a transform is checked when made, so the one that replays is a valid one: a constant profile's)
    again = T.Fog(profile="constant", lidar_target="velodyne").replay(params)(image=rgb, depth=rng, velodyne=pts)
    assert np.array_equal(again["image"], out["image"]) and np.array_equal(again["velodyne"], out["velodyne"])
    with pytest.raises(ValueError, match="lidar_target"):
        T.Fog(profile="constant").replay(params)
    brume.write_image(tmp_path / "rgb.pfm", rgb, bits="float")
    brume.write_image(tmp_path / "range.pfm", rng, bits="float", data=True)
    pts.tofile(tmp_path / "in.bin")
    run_cli("fog", "--image", tmp_path / "rgb.pfm", "--range", tmp_path / "range.pfm", "--out", tmp_path / "t.pfm",
            "--bits", "float", "--fov-y", 50, "--profile", "constant",
            "--lidar", tmp_path / "in.bin", "--lidar-out", tmp_path / "t.bin", "--record", tmp_path / "template.json")
    cli = json.loads((tmp_path / "template.json").read_text())
    for block, values in params["record"]["job"].items():
        cli["job"].setdefault(block, {}).update(values)
    (tmp_path / "rec.json").write_text(json.dumps(cli))
    run_cli("run", tmp_path / "rec.json", "--out-dir", tmp_path / "again")
    assert np.array_equal(read_bin(tmp_path / "again" / "t.bin"), out["velodyne"])
    assert np.array_equal(brume.read_image(tmp_path / "again" / "t.pfm").rgb, out["image"])
    # a clip: one draw, each frame's scan
    clip = T.Haze(visibility=(150, 600), seed=3, lidar_target="points")(
        images=[rgb, rgb[::-1].copy()], depths=[rng, rng], points=[pts, pts[:1000]], key="clip")
    assert len(clip["points"]) == 2 and clip["points"][1].shape == (1000, 4)
    v = clip["params"]["values"]
    assert np.array_equal(clip["points"][1], brume.haze(rgb[::-1].copy(), rng, lidar=pts[:1000], **v).lidar)


def test_haze_then_dof_fogs_the_scan_with_its_haze():
    rgb, rng = _scene()
    pts = scan(2000)
    t = T.HazeThenDof(visibility=(150, 600), dof_focus_distance=30, dof_coc_infinity=3, fov_x=40, seed=1,
                      lidar_target="points")
    out = t(image=rgb, depth=rng, points=pts, key="k")
    v = out["params"]["values"]
    rec = out["params"]["record"]
    assert rec["command"] == "haze+dof" and rec["lidar"]["alpha_per_m"] == 3.912 / v["haze"]["visibility"]
    assert np.array_equal(out["points"], brume.lidar.fog(pts, alpha=3.912 / v["haze"]["visibility"],
                                                         seed=v["haze"]["lidar-seed"]).points)
    again = t.replay(json.loads(json.dumps(out["params"])))(image=rgb, depth=rng, points=pts)
    assert np.array_equal(again["points"], out["points"]) and np.array_equal(again["image"], out["image"])


def test_transform_scan_bad_arguments():
    rgb, rng = _scene()
    with pytest.raises(ValueError, match="lidar_target='points': DepthOfField models no medium"):
        T.DepthOfField(lidar_target="points")
    with pytest.raises(ValueError, match="lidar_target=3"):
        T.Haze(lidar_target=3)
    with pytest.raises(ValueError, match="lidar_seed: a setting of the frame's LiDAR scan"):
        T.Haze(lidar_seed=3)
    t = T.Haze(visibility=300, lidar_target="points")
    with pytest.raises(ValueError, match="points: this transform fogs the frame's LiDAR scan"):
        t(image=rgb, depth=rng, key="k")
    with pytest.raises(ValueError, match=r"points: expected an \(N, 4\) float32"):
        t(image=rgb, depth=rng, points=scan(100).astype(np.float64), key="k")
    with pytest.raises(ValueError, match="points: a clip needs one scan per image"):
        t(images=[rgb, rgb], depths=[rng, rng], points=[scan(100)], key="k")


def test_transform_scan_as_a_torch_tensor():
    """A CPU torch scan comes back as a torch tensor with the numpy call's values."""
    torch = pytest.importorskip("torch")
    rgb, rng = _scene()
    pts = scan(1500)
    t = T.Haze(visibility=(40, 80), seed=4, lidar_target="points")
    ref = t(image=rgb, depth=rng, points=pts, key="t")["points"]
    out = t(image=rgb, depth=rng, points=torch.from_numpy(pts), key="t")["points"]
    assert isinstance(out, torch.Tensor) and out.dtype == torch.float32
    assert np.array_equal(out.numpy(), ref)


def test_transform_p_between_0_and_1_fogs_both_or_neither():
    """p=0.5 over twenty keys: where the draw applies, image and scan are
    both fogged (the scan with the draw's alpha); where it does not, both
    pass through as the same objects -- never one without the other."""
    rgb, rng = _scene(24, 32)
    pts = scan(500)
    t = T.Haze(p=0.5, visibility=(150, 600), seed=11, lidar_target="points")
    applied = 0
    for i in range(20):
        out = t(image=rgb, depth=rng, points=pts, key=f"k{i}")
        if out["params"]["applied"]:
            applied += 1
            assert out["image"] is not rgb and out["points"] is not pts
            assert out["params"]["record"]["lidar"]["alpha_per_m"] == 3.912 / out["params"]["values"]["visibility"]
        else:
            assert out["image"] is rgb and out["points"] is pts
    assert 3 <= applied <= 17  # both outcomes occur (binomial(20, 0.5): outside [3, 17] has p < 0.3 %)


def test_replay_fogs_no_scan_the_sample_did_not():
    """params drawn without lidar_target replayed by a transform with one:
    the image repeats, the scan passes through (the sample fogged none; a
    pipeline that fogs scans with LidarFog must not get them fogged twice)."""
    rgb, rng = _scene(24, 32)
    pts = scan(500)
    first = T.Haze(visibility=300, seed=2)(image=rgb, depth=rng, key="k")
    again = T.Haze(visibility=300, seed=2, lidar_target="points").replay(first["params"])(image=rgb, depth=rng,
                                                                                        points=pts)
    assert again["points"] is pts
    assert np.array_equal(again["image"], first["image"])


def test_rerun_checks_the_scan_and_the_calibration(demo, tmp_path):
    """brume.rerun of a CLI record that fogged a scan in a height-profile fog:
    a scan other than the recorded file's points (another count, or the same
    count with one value changed) and a calibration file changed since are
    refused, as `brume run` refuses changed files; the same ones replay."""
    (tmp_path / "calib.txt").write_text(CALIB)
    pts = scan()
    pts.tofile(tmp_path / "in.bin")
    d = demo["dir"]
    run_cli("fog", "--image", d / "clean.png", "--range", d / "range.exr", "--fov-y", 55, "--density", 0.05,
            "--falloff", 0.1, "--camera-height", 1.65, "--kitti-calib", tmp_path / "calib.txt",
            "--lidar", tmp_path / "in.bin", "--lidar-out", tmp_path / "s.bin", "--out", tmp_path / "o.png",
            "--record", tmp_path / "o.json")
    rec = json.loads((tmp_path / "o.json").read_text())
    same = brume.rerun(rec, demo["rgb"], demo["range"], lidar=pts)
    assert np.array_equal(same.lidar, read_bin(tmp_path / "s.bin"))
    with pytest.raises(ValueError, match="holds 99 points, the recorded scan"):
        brume.rerun(rec, demo["rgb"], demo["range"], lidar=pts[:99])
    other = pts.copy()
    other[7, 3] += 0.25
    with pytest.raises(ValueError, match="is not the recorded scan"):
        brume.rerun(rec, demo["rgb"], demo["range"], lidar=other)
    with open(tmp_path / "calib.txt", "a") as f:
        f.write("\n")
    with pytest.raises(ValueError, match="calib.txt' has changed"):
        brume.rerun(rec, demo["rgb"], demo["range"], lidar=pts)


def test_scan_sizes_beyond_an_images_rows():
    """A scan is not an image: more points than the images' 2^20 rows read
    (merged sweeps), an empty one is refused naming the keyword."""
    rgb, rng = _scene(8, 8)
    big = scan((1 << 20) + 5)
    r = brume.haze(rgb, rng, visibility=300, lidar=big)
    assert r.lidar.shape == big.shape
    with pytest.raises(ValueError, match="lidar holds no points"):
        brume.haze(rgb, rng, visibility=300, lidar=np.zeros((0, 4), np.float32))
