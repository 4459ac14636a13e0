"""The diffusion study's figures, drawn by matplotlib from its CSVs.

    python3 -m brume.plots STUDY_DIR [--out DIR]

reads what ``brume study diffusion --out-dir STUDY_DIR`` wrote:

- ``accuracy.csv`` (scheme,precision,backend,sigma,rms,iterations,spread)
  -> ``accuracy.png``: Hansard's Fig. 6, RMS error against a true Gaussian
  over sigma, the standard scheme above, the invariant schemes and the peers
  below, on one logarithmic RMS axis of whole decades so the panels compare;
- ``speed.csv`` (method,precision,backend,sigma,seconds,iterations,map,runs)
  -> ``speed.png``: Fig. 7, time over sigma for the standard scheme, the
  invariant schemes with the peers (constant sigma) and the space-variant
  haze map, on one logarithmic time axis;
- ``leakage.csv`` (method,edge_rate,backend,sigma_far,into_near_mean,
  into_near_max,into_far_mean) and the crops in ``leakage_crops/``
  -> ``leakage.png``: the near square's top-left corner for each method (3x,
  nearest neighbour, so every pixel shows), and the two leakage measures of
  the CPU rows as bars.

CPU rows are solid lines, GPU rows dashed; f16 is the lighter shade of its
scheme's colour. The figures are written into ``--out`` (default STUDY_DIR)
only when all three have been drawn (temporary files renamed into place), and
a missing or malformed CSV is an error naming the file, the line and the fix.
Headless: the Agg backend, no display needed.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import os
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the backend)
from matplotlib import image as mpimg  # noqa: E402

__all__ = ["PlotError", "read_study", "render_figures", "plot_study", "main", "FIGURES"]

FIGURES = ("accuracy.png", "speed.png", "leakage.png")

# Figure sizes in pixels at DPI: 960 px wide, 440 px per panel (as the study's
# figures have always been), so README layouts keep their proportions.
DPI = 100
WIDTH_PX = 960
PANEL_PX = 440

ACCURACY_COLUMNS = ["scheme", "precision", "backend", "sigma", "rms", "iterations", "spread"]
SPEED_COLUMNS = ["method", "precision", "backend", "sigma", "seconds", "iterations", "map", "runs"]
LEAKAGE_COLUMNS = ["method", "edge_rate", "backend", "sigma_far", "into_near_mean", "into_near_max", "into_far_mean"]

_NUMERIC = {"sigma", "rms", "iterations", "spread", "seconds", "runs", "sigma_far", "into_near_mean",
            "into_near_max", "into_far_mean"}


class PlotError(ValueError):
    """A study file is missing or cannot be read; the message names it and the fix."""


# ---- reading ---------------------------------------------------------------------------------------------------

def _read_csv(path: Path, columns: list[str]) -> list[dict]:
    if not path.is_file():
        raise PlotError(f"{path} not found; run `brume study diffusion --out-dir {path.parent}` first "
                        f"(it writes accuracy.csv, speed.csv and leakage.csv)")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise PlotError(f"{path} cannot be read as UTF-8 text ({e}); regenerate it with `brume study diffusion`")
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise PlotError(f"{path} is empty; expected the header {','.join(columns)} and rows")
    header = [h.strip() for h in rows[0]]
    if header != columns:
        raise PlotError(f"{path} line 1: the columns are {','.join(header)!r}, expected {','.join(columns)!r}; "
                        f"is this the study's {path.name}? Regenerate it with `brume study diffusion`")
    out = []
    for line, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(columns):
            raise PlotError(f"{path} line {line}: {len(row)} fields, expected {len(columns)} ({','.join(columns)})")
        rec = {}
        for name, value in zip(columns, row):
            value = value.strip()
            if name in _NUMERIC:
                try:
                    rec[name] = float(value)
                except ValueError:
                    raise PlotError(f"{path} line {line}: {name} {value!r} is not a number") from None
                if math.isnan(rec[name]) or (math.isinf(rec[name]) and name != "rms"):
                    raise PlotError(f"{path} line {line}: {name} {value!r} is not a finite number")
            else:
                rec[name] = value
        out.append(rec)
    if not out:
        raise PlotError(f"{path} has a header but no rows; the study did not finish? Rerun `brume study diffusion`")
    return out


def read_study(study_dir) -> dict:
    """The three CSVs of a study directory as lists of dicts (numbers as float)."""
    d = Path(study_dir)
    if not d.is_dir():
        raise PlotError(f"study directory {d} does not exist; give the --out-dir of `brume study diffusion`")
    return {
        "accuracy": _read_csv(d / "accuracy.csv", ACCURACY_COLUMNS),
        "speed": _read_csv(d / "speed.csv", SPEED_COLUMNS),
        "leakage": _read_csv(d / "leakage.csv", LEAKAGE_COLUMNS),
        "crops_dir": d / "leakage_crops",
    }


# ---- styling (the study's colours: one hue per scheme, light for f16) ------------------------------------------

def _colour(method: str, precision: str):
    f16 = precision == "f16"
    m = method[6:] if method.startswith("brume-") else method
    rgb = {
        "standard": (235, 120, 110) if f16 else (150, 0, 0),
        "invariant": (110, 160, 240) if f16 else (0, 40, 170),
        "invariant-exact": (110, 200, 110) if f16 else (0, 115, 0),
        "mipmap": (230, 140, 0),
        "gather": (140, 0, 170),
        "opencv-gaussianblur": (0, 0, 0),
    }.get(m, (128, 128, 128))  # memory floor
    return tuple(c / 255 for c in rgb)


def _label(method: str, precision: str, backend: str) -> str:
    m = method[6:] if method.startswith("brume-") else method
    fixed = {"opencv-gaussianblur": "OpenCV GaussianBlur", "memory-floor": "memory floor (copy × N)",
             "mipmap": "mip-map (peer)", "gather": "direct gather (peer)"}
    if m in fixed:
        return fixed[m]
    return f"{m} {precision}" + (" GPU" if backend == "gpu" else "")


def _crop_label(method: str, edge: str) -> str:
    return {"mipmap": "mip-map", "gather": "direct gather"}.get(method, f"{method}, {edge}")


def _decades(values):
    """Whole decades around the positive values (the panels of a figure share them)."""
    pos = [v for v in values if v > 0 and math.isfinite(v)]
    if not pos:
        return None
    lo, hi = 10 ** math.floor(math.log10(min(pos))), 10 ** math.ceil(math.log10(max(pos)))
    return (lo, hi if hi > lo else lo * 10)


def _backends(rows):
    present = {r["backend"] for r in rows}
    return [b for b in ("cpu", "gpu") if b in present] + sorted(present - {"cpu", "gpu"})


SIGMA_LABEL = r"$\sigma_\mathrm{ref}$ [px]"


def _series(ax, rows, x, y, method, precision, backend, **match):
    pts = sorted((r[x], r[y]) for r in rows
                 if r.get("scheme", r.get("method")) == method and r["precision"] == precision
                 and r["backend"] == backend and all(r[k] == v for k, v in match.items()))
    pts = [(a, b) for a, b in pts if b > 0 and math.isfinite(b)]  # a log axis cannot show 0
    if not pts:
        return False
    ax.plot([p[0] for p in pts], [p[1] for p in pts], color=_colour(method, precision),
            linestyle="--" if backend == "gpu" else "-", marker="o", markersize=4.5, linewidth=2,
            label=_label(method, precision, backend))
    return True


def _panel(ax, title, ylabel, ylim, legend_outside=False):
    ax.set_title(title)
    ax.set_xlabel(SIGMA_LABEL)
    ax.set_ylabel(ylabel)
    ax.set_yscale("log")
    if ylim:
        ax.set_ylim(*ylim)
    ax.set_xlim(left=0)
    ax.grid(True, which="major", color="0.88")
    if ax.lines:
        if legend_outside:
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=True)
        else:
            ax.legend(loc="best", fontsize=9, ncol=2 if len(ax.lines) > 6 else 1)
    else:
        ax.text(0.5, 0.5, "no data", transform=ax.transAxes, ha="center", va="center", color="0.4")


# ---- the figures -----------------------------------------------------------------------------------------------

def _accuracy(rows):
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(WIDTH_PX / DPI, 2 * PANEL_PX / DPI), dpi=DPI,
                                      layout="constrained")
    for b in _backends(rows):
        for pr in ("f32", "f16"):
            _series(top, rows, "sigma", "rms", "standard", pr, b)
            _series(bottom, rows, "sigma", "rms", "invariant", pr, b)
            _series(bottom, rows, "sigma", "rms", "invariant-exact", pr, b)
    _series(bottom, rows, "sigma", "rms", "mipmap", "f32", "cpu")
    _series(bottom, rows, "sigma", "rms", "gather", "f32", "cpu")
    ylim = _decades(r["rms"] for r in rows)
    _panel(top, "Standard scheme (eq. 13): RMS error against a true Gaussian", "RMS error", ylim)
    _panel(bottom, "Invariant schemes (eq. 18) and the peers", "RMS error", ylim)
    return fig


def _speed(rows):
    fig, (st, inv, var) = plt.subplots(3, 1, figsize=(WIDTH_PX / DPI, 3 * PANEL_PX / DPI), dpi=DPI,
                                       layout="constrained")
    for b in _backends(rows):
        for pr in ("f32", "f16"):
            _series(st, rows, "sigma", "seconds", "brume-standard", pr, b, map="constant")
            _series(inv, rows, "sigma", "seconds", "brume-invariant", pr, b, map="constant")
            _series(inv, rows, "sigma", "seconds", "brume-invariant-exact", pr, b, map="constant")
            _series(var, rows, "sigma", "seconds", "brume-invariant-exact", pr, b, map="varying")
    for m in ("opencv-gaussianblur", "mipmap", "gather", "memory-floor"):
        _series(inv, rows, "sigma", "seconds", m, "f32", "cpu", map="constant")
    for m in ("mipmap", "gather"):
        _series(var, rows, "sigma", "seconds", m, "f32", "cpu", map="varying")
    ylim = _decades(r["seconds"] for r in rows)
    _panel(st, "Standard scheme (eq. 13), constant σ", "time [s]", ylim, legend_outside=True)
    _panel(inv, "Invariant schemes (eq. 18) and the peers, constant σ", "time [s]", ylim, legend_outside=True)
    _panel(var, r"Space-variant haze map ($\sigma_0 + R'^{3/2}\,(\sigma - \sigma_0)$)", "time [s]", ylim,
           legend_outside=True)
    return fig


def _crop_file(crops_dir: Path, method: str, edge: str) -> Path:
    return crops_dir / (f"{method}.png" if edge in ("", "-") else f"{method}_{edge}.png")


def _leakage(rows, crops_dir: Path):
    cpu = [r for r in rows if r["backend"] == "cpu"]
    crops = []
    for r in cpu:
        f = _crop_file(crops_dir, r["method"], r["edge_rate"])
        if f.is_file():
            try:
                crops.append((_crop_label(r["method"], r["edge_rate"]), mpimg.imread(f)))
            except Exception as e:  # Pillow's errors vary by format problem
                raise PlotError(f"{f} cannot be read as an image ({e}); rerun `brume study diffusion`") from None
    cols = 4
    crop_rows = math.ceil(len(crops) / cols)
    tile_px, label_px, bars_px = 250, 26, 440
    height_px = crop_rows * (tile_px + label_px) + bars_px
    fig = plt.figure(figsize=(1000 / DPI, height_px / DPI), dpi=DPI)
    # Crops: a grid of axes without frames, 3x nearest neighbour (every pixel visible).
    for i, (label, img) in enumerate(crops):
        r, c = divmod(i, cols)
        x0 = (8 + c * 248) / 1000
        y0 = 1 - (8 + r * (tile_px + label_px) + 240) / height_px
        ax = fig.add_axes([x0, y0, 240 / 1000, 240 / height_px])
        ax.imshow(img, interpolation="nearest")
        ax.set_axis_off()
        fig.text(x0, y0 - 4 / height_px, label, ha="left", va="top", fontsize=10)
    # Bars: how much background reaches the sharp square, and how much of it spills into the background.
    ax = fig.add_axes([0.08, 0.2 * bars_px / height_px, 0.9, 0.68 * bars_px / height_px])
    names = [_crop_label(r["method"], r["edge_rate"]).replace(", ", "\n") for r in cpu]
    xs = range(len(cpu))
    w = 0.4
    sigma_far = cpu[0]["sigma_far"] if cpu else float("nan")
    ax.bar([x - w / 2 for x in xs], [r["into_near_mean"] for r in cpu], w, color=(0.85, 0.15, 0.1),
           label="background colour in the near square's 2 px rim (mean)")
    ax.bar([x + w / 2 for x in xs], [r["into_far_mean"] for r in cpu], w, color=(0.1, 0.6, 0.15),
           label=f"near colour in the background within σ_far = {sigma_far:g} px (mean)")
    ax.set_xticks(list(xs), names, fontsize=8, rotation=30, ha="right", rotation_mode="anchor")
    ax.set_ylabel("fraction of the other colour")
    ax.set_ylim(0, max([0.05] + [max(r["into_near_mean"], r["into_far_mean"]) for r in cpu]) * 1.15)
    ax.grid(True, axis="y", color="0.88")
    ax.set_axisbelow(True)
    ax.legend(loc="upper right", fontsize=9)
    ax.set_title("Leakage across a depth edge (CPU rows; the GPU rows are in leakage.csv)", fontsize=11)
    return fig


def render_figures(study: dict) -> dict:
    """{file name: PNG bytes} for the three figures of a read_study() result."""
    out = {}
    for name, make in (("accuracy.png", lambda: _accuracy(study["accuracy"])),
                       ("speed.png", lambda: _speed(study["speed"])),
                       ("leakage.png", lambda: _leakage(study["leakage"], Path(study["crops_dir"])))):
        fig = make()
        buf = io.BytesIO()
        # No creation time or version in the file: the same CSVs give the same bytes with this matplotlib.
        fig.savefig(buf, format="png", dpi=DPI, metadata={"Software": None})
        plt.close(fig)
        out[name] = buf.getvalue()
    return out


def plot_study(study_dir, out_dir=None) -> list[Path]:
    """Draws accuracy.png, speed.png and leakage.png from STUDY_DIR's CSVs into
    out_dir (default STUDY_DIR); all three appear, or none. Returns their paths."""
    pngs = render_figures(read_study(study_dir))
    out = Path(out_dir if out_dir is not None else study_dir)
    out.mkdir(parents=True, exist_ok=True)
    if not os.access(out, os.W_OK):
        raise PlotError(f"--out {out} is not writable; give a directory you can write to")
    temps = []
    try:
        for name, data in pngs.items():
            tmp = out / f".{name}.tmp{os.getpid()}"
            tmp.write_bytes(data)
            temps.append((tmp, out / name))
        for tmp, final in temps:
            os.replace(tmp, final)
    finally:
        for tmp, _ in temps:
            if tmp.exists():
                tmp.unlink()
    return [final for _, final in temps]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python3 -m brume.plots",
                                 description="Draw the diffusion study's figures (accuracy.png, speed.png, "
                                             "leakage.png) from the CSVs of `brume study diffusion`.")
    ap.add_argument("study_dir", help="the study's --out-dir (accuracy.csv, speed.csv, leakage.csv, leakage_crops/)")
    ap.add_argument("--out", help="directory for the PNGs (default: STUDY_DIR)")
    args = ap.parse_args(argv)
    try:
        for p in plot_study(args.study_dir, args.out):
            print(p)
    except PlotError as e:
        print(f"brume.plots: error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
