"""brume.plots: the diffusion study's figures from the committed CSVs
(docs/study/), their sizes and content, and the errors for missing or
malformed study files (nothing written then)."""

import shutil
import subprocess
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib import image as mpimg

ROOT = Path(__file__).resolve().parents[2]
STUDY = ROOT / "docs" / "study"

try:
    from brume import plots
except ImportError:  # the source tree without the compiled module: the namespace package under python/
    sys.path.insert(0, str(ROOT / "python"))
    from brume import plots

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
# 960 px wide, 440 px per panel; leakage: two rows of four 240 px crops with labels over the bars.
SIZES = {"accuracy.png": (880, 960), "speed.png": (1320, 960), "leakage.png": (992, 1000)}


def _has_colour(img, rgb, tol=12):
    """At least a few pixels within tol (8-bit) of rgb: a series drawn in that colour."""
    px = (img[..., :3] * 255).round()
    return int((np.abs(px - np.array(rgb)).max(axis=-1) <= tol).sum()) >= 20


def _copy_study(tmp_path, crops=True):
    d = tmp_path / "study"
    d.mkdir()
    for f in ("accuracy.csv", "speed.csv", "leakage.csv"):
        shutil.copy(STUDY / f, d / f)
    if crops:
        shutil.copytree(STUDY / "leakage_crops", d / "leakage_crops")
    return d


def test_figures_from_the_committed_csvs(tmp_path):
    out = tmp_path / "out"
    written = plots.plot_study(STUDY, out)
    assert sorted(p.name for p in written) == sorted(plots.FIGURES)
    imgs = {}
    for name, (h, w) in SIZES.items():
        data = (out / name).read_bytes()
        assert data[:8] == PNG_MAGIC, name
        img = mpimg.imread(out / name)
        assert img.shape[:2] == (h, w), name
        imgs[name] = img
    # The series are there, in the study's colours: standard f32 (dark red), invariant-exact f32 (green),
    # the gather peer (purple), OpenCV (black, speed); the leakage crops' pure red background and green square.
    assert _has_colour(imgs["accuracy.png"], (150, 0, 0))
    assert _has_colour(imgs["accuracy.png"], (0, 115, 0))
    assert _has_colour(imgs["accuracy.png"], (140, 0, 170))
    assert _has_colour(imgs["speed.png"], (140, 0, 170))
    assert _has_colour(imgs["speed.png"], (0, 0, 0), tol=2)
    assert _has_colour(imgs["leakage.png"], (255, 0, 0), tol=0)
    assert _has_colour(imgs["leakage.png"], (0, 255, 0), tol=0)


def test_same_csvs_same_bytes(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    plots.plot_study(STUDY, a)
    plots.plot_study(STUDY, b)
    for f in plots.FIGURES:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f


def test_quick_study_without_gpu_rows_or_crops(tmp_path):
    # A CPU-only study (--backend cpu) without the crops still gives the three figures; leakage is the bars alone.
    d = _copy_study(tmp_path, crops=False)
    for f in ("accuracy.csv", "speed.csv", "leakage.csv"):
        lines = (d / f).read_text().splitlines()
        (d / f).write_text("\n".join([lines[0]] + [l for l in lines[1:] if ",gpu," not in l]) + "\n")
    plots.plot_study(d)
    assert mpimg.imread(d / "leakage.png").shape[:2] == (440, 1000)
    assert mpimg.imread(d / "accuracy.png").shape[:2] == (880, 960)


def test_command_line(tmp_path):
    # The build-tree package (ctest sets PYTHONPATH), else the source tree's.
    env = {"PYTHONPATH": os.environ.get("PYTHONPATH", str(ROOT / "python")), "MPLBACKEND": "Agg", "PATH": "/usr/bin:/bin",
           "PYTHONDONTWRITEBYTECODE": "1", "HOME": str(tmp_path)}
    r = subprocess.run([sys.executable, "-m", "brume.plots", str(STUDY), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, env=env, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert sorted(Path(l).name for l in r.stdout.split()) == sorted(plots.FIGURES)
    bad = subprocess.run([sys.executable, "-m", "brume.plots", str(tmp_path / "nowhere")],
                         capture_output=True, text=True, env=env, cwd=tmp_path)
    assert bad.returncode == 2
    assert "brume.plots: error:" in bad.stderr and "does not exist" in bad.stderr


def test_missing_csv_is_named_and_nothing_is_written(tmp_path):
    d = _copy_study(tmp_path)
    (d / "leakage.csv").unlink()
    with pytest.raises(plots.PlotError) as e:
        plots.plot_study(d)
    assert "leakage.csv not found" in str(e.value)
    assert "brume study diffusion --out-dir" in str(e.value)
    assert not any((d / f).exists() for f in plots.FIGURES)


@pytest.mark.parametrize("mangle, expected", [
    (lambda t: t.replace("rms", "rmse", 1), "line 1: the columns are"),
    (lambda t: t.replace("0.00101654", "abc", 1), "line 2: rms 'abc' is not a number"),
    (lambda t: t.replace("standard,f16,cpu,1.5,0.00101849,3,1.11802", "standard,f16,cpu,1.5", 1),
     "line 3: 4 fields, expected 7"),
    (lambda t: t.splitlines()[0] + "\n", "has a header but no rows"),
    (lambda t: "", "is empty"),
])
def test_corrupt_csv_gives_a_clear_error(tmp_path, mangle, expected):
    d = _copy_study(tmp_path)
    (d / "accuracy.csv").write_text(mangle((d / "accuracy.csv").read_text()))
    with pytest.raises(plots.PlotError) as e:
        plots.plot_study(d)
    assert expected in str(e.value)
    assert "accuracy.csv" in str(e.value)
    assert not any((d / f).exists() for f in plots.FIGURES)


def test_binary_garbage_and_bad_crop(tmp_path):
    d = _copy_study(tmp_path)
    (d / "speed.csv").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(plots.PlotError, match="speed.csv cannot be read as UTF-8"):
        plots.plot_study(d)
    (tmp_path / "second").mkdir()
    d2 = _copy_study(tmp_path / "second")
    (d2 / "leakage_crops" / "gather.png").write_bytes(b"not a png")
    with pytest.raises(plots.PlotError, match="gather.png cannot be read as an image"):
        plots.plot_study(d2)
    assert not any((d2 / f).exists() for f in plots.FIGURES)
