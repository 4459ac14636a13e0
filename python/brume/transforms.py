"""brume.transforms: the effects as augmentation transforms for training
pipelines (issue #42), in the albumentations call protocol without importing
albumentations, for numpy and torch images, seeded, replayable, fork-safe.

    t = brume.transforms.Haze(visibility=(150, 600), albedo=0.9, seed=7)
    out = t(image=img, depth=range_m, key="Art/view1.png")
    out["image"], out["depth"], out["params"]      # params: {"values", "seed", "key", "record"}
    t.replay(out["params"])(image=img, depth=range_m)["image"]   # the same bits

The classes are made from the library's list of commands
(``_brume._commands()``): every effect ``brume sample`` draws for and that
runs on ``(rgb, range)`` arrays gets one (Haze, Aerial, Fog, DepthOfField),
every chain of them one more (HazeThenDof); their parameters, ranges and
default distributions are the tables' (``brume sample``'s, with their
reasons in each effect's file). See docs/transforms.md.
"""
import hashlib
import json
import math
import multiprocessing
import sys

import numpy as np

from . import _brume

__all__ = ["PointsTransform", "Transform", "loguniform", "uniform", "choice", "seed"]

_SAMPLER = "brume-sample-v1"


# ---- distributions in physical units ------------------------------------------------------------
class _Spec:
    """A distribution a parameter is drawn from, as the sampler's spec text."""

    def __init__(self, text):
        self.text = text

    def __repr__(self):
        return self.text


def uniform(lo, hi):
    """Uniform in [lo, hi); the same as passing the tuple ``(lo, hi)``."""
    return _Spec(f"uniform({lo!r}, {hi!r})")


def loguniform(lo, hi):
    """Log-uniform in [lo, hi), lo > 0 (a visibility, a density)."""
    return _Spec(f"loguniform({lo!r}, {hi!r})")


def choice(*items):
    """One of the items, each with probability 1/n (numbers or names)."""
    if not items:
        raise ValueError("brume.transforms.choice(): give at least one item")
    return _Spec("choice(" + ", ".join(str(i) for i in items) + ")")


def seed():
    """A whole-number parameter drawn per key (a drop field's seed): the top 53
    bits of the sampler's hash, so that no two keys share it."""
    return _Spec("seed()")


def _spec_text(name, v):
    """The sampler's spec text for what a user gave: a fixed value, a
    (lo, hi) tuple (uniform), or a distribution above."""
    if isinstance(v, _Spec):
        return v.text
    if isinstance(v, tuple):
        if len(v) != 2 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            raise ValueError(f"{name}={v!r}: a tuple is a uniform range (lo, hi) of two numbers; use "
                             f"brume.transforms.choice(...) for a set of values")
        return f"uniform({v[0]!r}, {v[1]!r})"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list,)):
        return ",".join(str(x) for x in v)  # an RGB triple, as the flag takes it
    if v is None:
        return "auto"
    return str(v)


def _check_p_seed(p, seed):
    """Every transform's p and seed (ValueError naming the argument)."""
    if isinstance(p, bool) or not isinstance(p, (int, float)) or not 0.0 <= p <= 1.0:
        raise ValueError(f"p={p!r}: the probability of applying, a number in [0, 1]")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed={seed!r}: a non-negative integer")


def _unit(seed, key, name):
    """u in [0, 1) of the library's sampler for (seed, key, name): the scheme
    brume-sample-v1 (brume/sample.hpp), here for the transform's own draws
    (whether it applies: name "p")."""
    msg = b"brume-sample-v1\0" + str(seed).encode() + b"\0" + key.encode() + b"\0" + name.encode()
    n = int.from_bytes(hashlib.sha256(msg).digest()[:8], "big")
    return (n >> 11) / 2.0 ** 53


# ---- images and depth in, and back out in their own type -----------------------------------------
def _srgb_decode(x):
    x = np.asarray(x, np.float32)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _srgb_encode(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, x * 12.92, 1.055 * np.power(x, 1 / 2.4) - 0.055).astype(np.float32)


def _is_torch(x):
    t = sys.modules.get("torch")
    return t is not None and isinstance(x, t.Tensor)


class _Image:
    """An image as the library reads it (H x W x 3 float32 linear, or an
    integer array with its transfer), and how to give the result back in the
    caller's type, dtype, layout and range."""

    def __init__(self, x, transfer, arg):
        self.torch = _is_torch(x)
        if self.torch:
            if x.device.type != "cpu":
                raise ValueError(f"{arg}: a torch tensor on {x.device}; brume runs on CPU tensors "
                                 f"(call .cpu() first)")
            if x.ndim != 3 or x.shape[0] not in (3, 4):
                raise ValueError(f"{arg}: a torch tensor must be C x H x W with 3 (or 4) channels, got "
                                 f"shape {tuple(x.shape)}")
            self.torch_dtype = x.dtype
            a = x.detach().permute(1, 2, 0).contiguous().numpy()  # the one copy: CHW -> interleaved
        else:
            if not isinstance(x, np.ndarray):
                raise ValueError(f"{arg}: expected a numpy array H x W x 3 or a torch tensor C x H x W, got "
                                 f"{type(x).__name__}")
            a = x
        if a.ndim != 3 or a.shape[2] not in (3, 4):
            raise ValueError(f"{arg}: expected H x W x 3 (or x 4), got shape {a.shape} ({a.dtype})")
        self.dtype = a.dtype
        self.shape = a.shape
        if a.dtype == np.uint8 or a.dtype == np.uint16:
            self.transfer = transfer or "srgb"
        elif a.dtype == np.float32 or a.dtype == np.float64:
            self.transfer = transfer or "linear"
        else:
            raise ValueError(f"{arg}: dtype {a.dtype} is not one of uint8, uint16, float32, float64")
        if self.transfer not in ("srgb", "linear"):
            raise ValueError(f"transfer={self.transfer!r}: 'srgb' or 'linear'")
        if a.dtype.kind == "f" and self.transfer == "srgb":
            a = _srgb_decode(a[..., :3])
        if a.shape[2] == 4:
            self.alpha = a[..., 3:].copy()
        self.array = a  # float32 linear: read in place by the library
        self.kw = {"transfer": self.transfer} if a.dtype.kind == "u" else {}

    def back(self, rgb):
        """The library's linear float32 H x W x 3 in the caller's form."""
        if self.dtype.kind == "u":
            top = np.iinfo(self.dtype).max
            out = rgb if self.transfer == "linear" else _srgb_encode(rgb)
            out = np.floor(np.clip(out, 0.0, 1.0) * top + 0.5).astype(self.dtype)
        elif self.transfer == "srgb" or self.torch:
            out = _srgb_encode(rgb) if self.transfer == "srgb" else np.clip(rgb, 0.0, 1.0)
            out = out.astype(self.dtype, copy=False)
        else:
            out = rgb.astype(self.dtype, copy=False)
        if self.shape[2] == 4:  # alpha passes through untouched
            out = np.concatenate([out, self.alpha.astype(out.dtype)], axis=2)
        if self.torch:
            torch = sys.modules["torch"]
            return torch.from_numpy(np.ascontiguousarray(out.transpose(2, 0, 1)))
        return out


def _depth_array(d, shape, kind, unit, intr, arg):
    """Depth as the library reads it: H x W float32 metres along each pixel's
    ray, unknown (0, NaN, inf, negative) as NaN."""
    if _is_torch(d):
        d = d.detach().cpu().numpy()
        if d.ndim == 3 and d.shape[0] == 1:
            d = d[0]
    if not isinstance(d, np.ndarray):
        raise ValueError(f"{arg}: expected a numpy array H x W (or a torch tensor), got {type(d).__name__}")
    if d.ndim == 3 and d.shape[2] == 1:
        d = d[..., 0]
    if d.shape != tuple(shape):
        raise ValueError(f"{arg}: shape {d.shape} does not match the image's {tuple(shape)} (H x W); give a depth "
                         f"map of the image's size")
    if d.dtype.kind in "ui" and kind == "disparity":  # a stored disparity (a Middlebury PNG): 0 is unknown
        d = np.where(d == 0, np.nan, d.astype(np.float64))
    elif d.dtype.kind in "ui":
        if unit is None:
            raise ValueError(f"depth_unit: {arg} is {d.dtype} (integer); say its unit: depth_unit='m' or 'mm' "
                             f"(a 16-bit PNG in millimetres is depth_unit='mm')")
    elif d.dtype.kind != "f":
        raise ValueError(f"{arg}: dtype {d.dtype} is not a depth (float or unsigned integer)")
    scale = 0.001 if unit == "mm" else 1.0
    if kind == "range" and d.dtype == np.float32 and scale == 1.0:
        # metres as the library takes them (NaN: unknown): read in place unless 0, inf or < 0 must become NaN
        invalid = (d <= 0) | np.isinf(d)
        if not invalid.any():
            return d
        v = d.copy()
        v[invalid] = np.nan
        return v
    if kind in ("range", "z"):
        v = d.astype(np.float64) * scale
    elif kind == "disparity":  # pixels: z = fx baseline / (scale d + doffs), as brume.depth.convert
        if intr.get("baseline") is None:
            raise ValueError("baseline: depth_kind='disparity' needs baseline= (metres between the cameras), or "
                             "calib= (a Middlebury 2014 / ETH3D calib.txt)")
        with np.errstate(divide="ignore", invalid="ignore"):
            v = intr["fx"] * intr["baseline"] / (intr.get("disparity_scale", 1.0) * d.astype(np.float64)
                                                 + intr.get("disparity_offset", 0.0))
    else:  # inverse depth 1/z in 1/unit: z = unit / d metres
        with np.errstate(divide="ignore", invalid="ignore"):
            v = scale / d.astype(np.float64)
    v[~np.isfinite(v) | (v <= 0)] = np.nan
    if kind != "range":  # z along the optical axis -> range along the pixel's ray
        h, w = shape
        u = (np.arange(w) - intr["cx"]) / intr["fx"]
        t = (np.arange(h) - intr["cy"]) / intr["fy"]
        v = v * np.sqrt(1.0 + u[None, :] ** 2 + t[:, None] ** 2)
    return v.astype(np.float32)


class _Points:
    """A LiDAR scan as the library reads it (an (N, 4) float32 numpy array of
    x, y, z, intensity, read in place), and how to give the foggy one back in
    the caller's type (numpy, or a CPU torch tensor)."""

    def __init__(self, x, arg):
        self.torch = _is_torch(x)
        if self.torch:
            if x.device.type != "cpu":
                raise ValueError(f"{arg}: a torch tensor on {x.device}; call .cpu() first")
            a = x.detach().numpy()
        elif isinstance(x, np.ndarray):
            a = x
        else:
            raise ValueError(f"{arg}: expected an (N, 4) numpy array or torch tensor, got {type(x).__name__}")
        if a.ndim != 2 or a.shape[1] != 4 or a.dtype != np.float32:
            raise ValueError(f"{arg}: expected an (N, 4) float32 array of x, y, z, intensity, got shape {a.shape} "
                             f"({a.dtype})")
        self.array = a

    def back(self, points):
        return sys.modules["torch"].from_numpy(points) if self.torch else points


# ---- the transforms ---------------------------------------------------------------------------
_COMMANDS = {c["name"]: c for c in _brume._commands()}
_INTRINSICS = ("fx", "fy", "cx", "cy", "fov_x", "fov_y", "baseline", "calib")
_DISPARITY = ("disparity_scale", "disparity_offset")  # (doffs: disparity_offset's other name)
_OWN = ("p", "seed", "depth_kind", "depth_unit", "transfer", "per_frame", "lidar_target") + _INTRINSICS + _DISPARITY


def _canonical(command, name):
    """The record name of a sampled parameter given as `name`, or None when
    the name is not one of the effect's own (a shared block's keyword)."""
    for canon, others in command["sampling"].get("params", {}).items():
        if name == canon or name in others:
            return canon
    return None


class _Stage:
    """One effect of a transform: its command, its distributions (the
    table's defaults overridden by the user's) and its other keywords."""

    def __init__(self, command, kw, where):
        self.command = command
        self.specs = {}
        self.fixed = {}
        for name, v in kw.items():
            canon = _canonical(command, name)
            if canon is not None:
                self.specs[canon] = _spec_text(name, v)
            elif name in command["keywords"]:
                if isinstance(v, (_Spec, tuple)):
                    raise ValueError(f"{name}={v!r}: {name} is not one of the parameters {command['name']} draws "
                                     f"(those of `brume sample {command['name']}`); give it a fixed value")
                self.fixed[name] = v
            else:
                raise TypeError(f"{where}: unknown argument {name!r}; the parameters are "
                                f"{', '.join(command['keywords'])} and {', '.join(_OWN)}")
        # every value each distribution can produce is checked against the table now (ValueError naming it),
        # and every combination of their ends by the run's own checks
        self._check_draws(where)

    def _check_draws(self, where):
        """The run's own checks (the same as the command line's: combinations,
        the camera a height profile or planar depth needs), made now on every
        set of values the distributions can draw at their ends -- a fixed
        value, both bounds of each range, each choice -- with the fixed
        keywords, so that a transform that would fail on some draw fails
        here, not in a DataLoader worker."""
        failures, passed = [], False
        try:
            corners = _brume._sample_corners(self.command["name"], **self.specs)
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None
        for values in corners:
            try:
                _brume._check_call(self.command["function"], **self.fixed, **values)
                passed = True
            except (ValueError, TypeError) as e:
                failures.append((type(e), str(e), values))
        if not failures:
            return
        # What every draw fails on (the fixed keywords') first; else the first draw that fails.
        counts = {}
        for f in failures:
            counts[f[1]] = counts.get(f[1], 0) + 1
        kind, message, values = max(failures, key=lambda f: counts[f[1]])
        message = message.split("(): ", 1)[1] if message.startswith("brume.") and "(): " in message else message
        drawn = {k: v for k, v in values.items() if k not in self._fixed_specs()}
        if passed and drawn:  # some draws pass: say which one fails
            shown = ", ".join(f"{k.replace('-', '_')}={v!r}" for k, v in sorted(drawn.items()))
            message += f" (when the draw gives {shown})"
        raise kind(f"{where}: {message}") from None

    def _fixed_specs(self):
        """The sampled parameters given as one fixed value (not drawn)."""
        out = set()
        for name, text in self.specs.items():
            if "(" not in text:
                out.add(name)
        return out

    @property
    def function(self):  # looked up on use: a transform pickles (spawned workers) without the module's functions
        return getattr(_brume, self.command["function"])

    def draw(self, seed, key):
        return _brume.random_params(self.command["name"], seed, key, **self.specs)


class _Keyed:
    """What every transform shares: p and seed, the key of a call, whether a
    draw applies, and the check of a replay's params."""

    def __init__(self, p, seed):
        _check_p_seed(p, seed)
        self.p, self.seed = float(p), seed
        self._calls = 0

    def _auto_key(self):
        """(call counter, worker id) when no key= is given: a torch DataLoader
        worker's id, a multiprocessing worker's index, else 0."""
        worker = 0
        torch = sys.modules.get("torch")
        info = torch.utils.data.get_worker_info() if torch is not None and hasattr(torch, "utils") else None
        if info is not None:
            worker = info.id
        elif multiprocessing.current_process()._identity:
            worker = multiprocessing.current_process()._identity[-1]
        key = f"call:{worker}:{self._calls}"
        self._calls += 1
        return key

    def _applies(self, key):
        return self.p >= 1.0 or _unit(self.seed, key, "p") < self.p

    def _noise_seed(self, key):
        """The seed of a scan's fog returns' range noise for `key`: 53 bits of
        the same hash scheme (name "noise-seed")."""
        return int(_unit(self.seed, key, "noise-seed") * 2.0 ** 53)

    @staticmethod
    def _check_params(params):
        if not isinstance(params, dict) or "record" not in params or "applied" not in params:
            raise ValueError("params: a transform call's \"params\" dict (with \"record\" and \"applied\")")


class Transform(_Keyed):
    """An effect (or a chain of effects) of the library as an augmentation
    transform; the classes below (Haze, Fog, Aerial, DepthOfField,
    HazeThenDof) are made from the library's list of commands.

    lidar_target="points" (the camera effects with a medium: Haze, Fog,
    Aerial, HazeThenDof) fogs the frame's LiDAR scan, given as that target of
    the call, with the image's medium from the same draw (brume.haze(...,
    lidar=points)); without it every target passes through untouched."""

    _commands = ()  # the commands run, in order: ("haze",) or ("haze", "dof")
    _prefixes = ()  # each later stage's keyword prefix ("dof_")

    def __init__(self, p=1.0, seed=0, depth_kind="range", depth_unit=None, transfer=None, per_frame=False,
                 fx=None, fy=None, cx=None, cy=None, fov_x=None, fov_y=None, baseline=None, calib=None,
                 disparity_scale=None, disparity_offset=None, lidar_target=None, **params):
        where = f"brume.transforms.{type(self).__name__}()"
        super().__init__(p, seed)
        if "doffs" in params:  # Middlebury's name for the disparity offset
            if disparity_offset is not None:
                raise TypeError(f"{where}: disparity_offset and doffs are the same keyword; give one")
            disparity_offset = params.pop("doffs")
        if depth_kind not in ("range", "z", "disparity", "inverse"):
            raise ValueError(f"depth_kind={depth_kind!r}: 'range' (metres along the ray), 'z' (along the optical "
                             f"axis), 'disparity' (pixels; needs fx, baseline) or 'inverse' (1/z)")
        if depth_unit not in (None, "m", "mm"):
            raise ValueError(f"depth_unit={depth_unit!r}: 'm' or 'mm'")
        if transfer not in (None, "srgb", "linear"):
            raise ValueError(f"transfer={transfer!r}: 'srgb' or 'linear' (default: srgb for integer images, "
                             f"linear for float)")
        self.depth_kind, self.depth_unit = depth_kind, depth_unit
        self.transfer, self.per_frame = transfer, bool(per_frame)
        self.intrinsics = {k: v for k, v in dict(fx=fx, fy=fy, cx=cx, cy=cy, fov_x=fov_x, fov_y=fov_y,
                                                 baseline=baseline).items() if v is not None}
        for name, v in (("fx", fx), ("fy", fy), ("fov_x", fov_x), ("fov_y", fov_y), ("baseline", baseline)):
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0):
                raise ValueError(f"{name}={v!r}: a number > 0")
        self.disparity = {}
        for name, v in (("disparity_scale", disparity_scale), ("disparity_offset", disparity_offset)):
            if v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{name}={v!r}: a finite number (disparity = disparity_scale * stored + "
                                 f"disparity_offset, in pixels)")
            if depth_kind != "disparity":
                raise ValueError(f"{name}={v!r}: it converts a disparity; depth_kind={depth_kind!r} takes no "
                                 f"disparity (give depth_kind='disparity', or drop it)")
            self.disparity[name] = float(v)
        self.calib = None
        if calib is not None:
            import os
            given = [k for k in ("fx", "fy", "cx", "cy", "baseline") if k in self.intrinsics]
            given += ["disparity_offset"] if "disparity_offset" in self.disparity else []
            if given:
                raise ValueError(f"calib={calib!r} gives the camera (focal length, principal point, baseline, "
                                 f"doffs); drop {', '.join(given)}, or drop calib")
            c = _brume._read_stereo_calib(os.fspath(calib))  # (FileNotFoundError / ValueError naming it)
            self.calib = os.fspath(calib)
            self.intrinsics.update({k: v for k, v in dict(fx=c["f_px"], fy=c["f_px"], cx=c["cx"], cy=c["cy"]).items()
                                    if math.isfinite(v)})
            if depth_kind == "disparity":
                self.intrinsics["baseline"] = c["baseline_m"]
                self.disparity["disparity_offset"] = c["doffs_px"]
        if depth_kind != "range" and "fx" not in self.intrinsics and "fov_x" not in self.intrinsics:
            raise ValueError(f"fx: depth_kind={depth_kind!r} needs the camera's intrinsics (fx [px], or fov_x "
                             f"[degrees]; fy, cx, cy default to fx and the image centre; or calib=, a "
                             f"calib.txt)")
        if depth_kind == "disparity" and "baseline" not in self.intrinsics:
            raise ValueError("baseline: depth_kind='disparity' needs baseline= (metres between the cameras), or "
                             "calib= (a Middlebury 2014 / ETH3D calib.txt)")
        # split the keywords among the stages: a later stage's carry its prefix (dof_f_number)
        per_stage = [dict() for _ in self._commands]
        for name, v in params.items():
            i = 0
            for j, pre in enumerate(self._prefixes, start=1):
                if name.startswith(pre):
                    i, name = j, name[len(pre):]
            per_stage[i][name] = v
        self._stages = []
        for c, kw in zip(self._commands, per_stage):
            command = _COMMANDS[c]
            for k in _INTRINSICS:  # the effects that take intrinsics (fog, dof) get the transform's
                if self.calib is not None and k == "calib" and k in command["keywords"]:
                    kw.setdefault("calib", self.calib)  # (its file: the record names it, as the CLI's)
                elif self.calib is None and k in self.intrinsics and k in command["keywords"]:
                    kw.setdefault(k, self.intrinsics[k])
            self._stages.append(_Stage(command, kw, where))
        if lidar_target is None:
            for st in self._stages:
                for name in st.fixed:
                    if name.startswith("lidar_"):
                        raise ValueError(f"{name}: a setting of the frame's LiDAR scan, but this transform fogs "
                                         f"none; give lidar_target= (the call's target holding the scan, e.g. "
                                         f"'points'), or drop {name}")
        else:
            reserved = ("image", "depth", "key", "params", "images", "depths")
            if not isinstance(lidar_target, str) or not lidar_target or lidar_target in reserved:
                raise ValueError(f"lidar_target={lidar_target!r}: the name of the call's target that holds the "
                                 f"frame's LiDAR scan, e.g. 'points' (not {', '.join(reserved)}: the call's own)")
            medium = self._chain() or self._stages[0].command
            if "lidar" not in medium.get("keyword_arrays", []):
                raise ValueError(f"lidar_target={lidar_target!r}: {type(self).__name__} models no medium to fog a "
                                 f"scan with; the transforms that do: "
                                 f"{', '.join(sorted(n for n, c in _CLASSES.items() if issubclass(c, Transform) and c._fogs_scans()))}")
        self.lidar_target = lidar_target

    @classmethod
    def _fogs_scans(cls):
        c = _COMMANDS.get("+".join(cls._commands))
        return c is not None and "lidar" in c.get("keyword_arrays", [])

    # ---- keys and draws ------------------------------------------------------------------------
    def draw(self, key):
        """The parameters for `key`: whether it applies, and each stage's
        values (the library's sampler: a function of (seed, key, name)); with
        lidar_target, the first stage's also the scan's noise seed
        ("lidar-seed", unless given fixed)."""
        applied = self._applies(key)
        values = [s.draw(self.seed, key if i == 0 else f"{key}/{s.command['name']}")
                  for i, s in enumerate(self._stages)] if applied else []
        if (applied and self.lidar_target is not None and "lidar_seed" not in self._stages[0].fixed
                and "lidar_seed" in self._stages[0].command["keywords"]):  # (rain's scan takes the rain's seed)
            values[0]["lidar-seed"] = self._noise_seed(key)
        return applied, values

    # ---- the call protocol -----------------------------------------------------------------------
    def __call__(self, image=None, depth=None, key=None, images=None, depths=None, **targets):
        if images is not None:
            return self._clip(images, depths, key, targets)
        if image is None or depth is None:
            raise ValueError("image and depth: call t(image=..., depth=...) or, for a clip, t(images=[...], "
                             "depths=[...])")
        scan = self._scan(targets, None)
        key = self._auto_key() if key is None else str(key)
        applied, values = self.draw(key)
        out_image, record, out_scan = (self._apply(image, depth, values, "image", "depth", scan=scan) if applied
                                       else (image, None, scan))
        params = self._params(key, applied, values, record)
        out = dict(targets, image=out_image, depth=depth, params=params)
        if self.lidar_target is not None:
            out[self.lidar_target] = out_scan
        return out

    def _scan(self, targets, frames):
        """The scan target (with lidar_target; a clip's: one scan per frame), or None."""
        if self.lidar_target is None:
            return None
        name = self.lidar_target
        if name not in targets:
            raise ValueError(f"{name}: this transform fogs the frame's LiDAR scan given as {name}=... "
                             f"(lidar_target={name!r}); pass it, or make the transform without lidar_target")
        scan = targets[name]
        if frames is not None and (not isinstance(scan, (list, tuple)) or len(scan) != frames):
            raise ValueError(f"{name}: a clip needs one scan per image ({frames} images), as a list")
        return scan

    def _clip(self, images, depths, key, targets):
        if depths is None or len(depths) != len(images):
            raise ValueError(f"depths: a clip needs one depth per image ({len(images)} images, "
                             f"{'none' if depths is None else len(depths)} depths)")
        scans = self._scan(targets, len(images))
        key = self._auto_key() if key is None else str(key)
        out, frames, out_scans = [], [], []
        applied, values = self.draw(key)
        for i, (im, d) in enumerate(zip(images, depths)):
            if self.per_frame:
                applied, values = self.draw(f"{key}/{i}")
            scan = scans[i] if scans is not None else None
            o, rec, sc = (self._apply(im, d, values, f"images[{i}]", f"depths[{i}]", scan=scan,
                                      scan_arg=f"{self.lidar_target}[{i}]") if applied else (im, None, scan))
            out.append(o)
            out_scans.append(sc)
            frames.append(self._params(f"{key}/{i}" if self.per_frame else key, applied, values, rec))
        params = frames[0] if not self.per_frame else {"seed": self.seed, "key": key, "frames": frames}
        if not self.per_frame:
            params = dict(params, records=[f["record"] for f in frames])
            params["record"] = frames[0]["record"]
        result = dict(targets, images=out, depths=list(depths), params=params)
        if scans is not None:
            result[self.lidar_target] = out_scans
        return result

    def _params(self, key, applied, values, record):
        vals = values[0] if len(values) == 1 else {s.command["name"]: v for s, v in zip(self._stages, values)}
        return {"values": vals, "applied": applied, "seed": self.seed, "key": key, "record": record}

    def _apply(self, image, depth, values, image_arg, depth_arg, jobs=None, scan=None, scan_arg=None):
        """The image (and the scan, when given) through the effect: (image,
        record, scan), each in the caller's type."""
        img = _Image(image, self.transfer, image_arg)
        pts = _Points(scan, scan_arg or self.lidar_target) if scan is not None else None
        lidar = {"lidar": pts.array} if pts is not None else {}
        h, w = img.shape[:2]
        intr = dict(self.intrinsics)
        if self.depth_kind != "range":
            if "fx" not in intr:
                intr["fx"] = (w / 2.0) / math.tan(math.radians(intr["fov_x"]) / 2.0)
            if "fy" not in intr:
                intr["fy"] = ((h / 2.0) / math.tan(math.radians(intr["fov_y"]) / 2.0) if "fov_y" in intr
                              else intr["fx"])
            intr.setdefault("cx", (w - 1) / 2.0)
            intr.setdefault("cy", (h - 1) / 2.0)
        rng = _depth_array(depth, (h, w), self.depth_kind, self.depth_unit, dict(intr, **self.disparity), depth_arg)
        rgb, kw = img.array, img.kw
        chain = self._chain() if jobs is None or len(jobs) == 1 else None  # (a record of stages: in turn)
        if chain is not None:  # the chain's own function: the range prepared once, one record `brume run` takes
            f = getattr(_brume, chain["function"])
            if jobs is not None:
                r = f(rgb, rng, job=jobs[0], **kw, **lidar)
            else:
                r = f(rgb, rng, **kw, **self._chain_keywords(chain, values), **lidar)
            return img.back(r.rgb), r.record, (pts.back(r.lidar) if pts is not None else None)
        records, foggy = [], None
        for i, s in enumerate(self._stages):  # (a scan goes with the first stage, the one with the medium)
            if jobs is not None:
                r = s.function(rgb, rng, job=jobs[i], **kw, **lidar)
            else:
                r = s.function(rgb, rng, **kw, **s.fixed, **values[i], **lidar)
            if lidar:
                foggy = pts.back(r.lidar)
            records.append(r.record)
            rgb, kw, lidar = r.rgb, {}, {}
        record = records[0] if len(records) == 1 else {"stages": records}
        return img.back(rgb), record, foggy

    def _chain(self):
        """A chain's command when it runs on arrays itself (haze+dof:
        brume.haze_dof), else None (each stage's function in turn)."""
        if len(self._commands) < 2:
            return None
        c = _COMMANDS.get("+".join(self._commands))
        return c if c is not None and c.get("function") and c["arrays"] == ["rgb", "range"] else None

    def _chain_keywords(self, chain, values):
        """Each stage's fixed and drawn values as the chain's keywords: a later
        stage's own parameters with the chain's prefix (dof_f_number), its
        shared blocks' (the intrinsics) as they are."""
        kw = {}
        prefix = chain["stage_prefix"].replace("-", "_")
        for i, (s, v) in enumerate(zip(self._stages, values)):
            for name, x in list(s.fixed.items()) + list(v.items()):
                key = name.replace("-", "_")
                if i > 0 and prefix + key in chain["keywords"]:
                    key = prefix + key
                kw[key] = x
        return kw

    # ---- replay ------------------------------------------------------------------------------
    def replay(self, params):
        """A callable that repeats the sample `params` (a call's "params",
        also after a JSON round trip) bit for bit on the same inputs:
        replay(params)(image=..., depth=...)."""
        self._check_params(params)
        record = params["record"]
        parent = self
        if params["applied"] and "lidar" in record.get("job", {}) and self.lidar_target is None:
            raise ValueError("params: this sample also fogged a LiDAR scan; replay it with a transform made with "
                             "lidar_target= (the name of the scan's target, e.g. 'points')")

        def again(image=None, depth=None, **targets):
            scan = parent._scan(targets, None)
            out = dict(targets, image=image, depth=depth, params=params)
            if not params["applied"]:
                return out
            recs = record["stages"] if "stages" in record else [record]
            jobs = [r["job"] for r in recs]
            # A sample that fogged no scan (drawn without lidar_target) leaves the scan as it is: a replay
            # repeats the sample, it does not fog what the sample did not.
            fogged = scan is not None and any("lidar" in j for j in jobs)
            out["image"], _, foggy = parent._apply(image, depth, None, "image", "depth", jobs=jobs,
                                                   scan=scan if fogged else None)
            if fogged:
                out[parent.lidar_target] = foggy
            return out

        return again

    def __repr__(self):
        specs = {k: v for s in self._stages for k, v in s.specs.items()}
        return f"{type(self).__name__}(p={self.p}, seed={self.seed}, {json.dumps(specs)})"


class PointsTransform(_Keyed):
    """An effect on a LiDAR scan (the LiDAR fog's) as an augmentation transform:
    t(points=..., key=..., **targets) -> {"points", "params", **targets}.
    points: an (N, 4) float32 array (or CPU torch tensor) of x, y, z [m] and
    intensity, as KITTI's .bin holds them; the result comes back in the same
    type. The noise of the fog returns gets its own seed per draw (from seed
    and key, recorded with the values), so two keys never share a noise
    pattern and a replay repeats it. (A scan fogged with its camera image's
    medium: the camera transforms' lidar_target.)"""

    _commands = ()

    def __init__(self, p=1.0, seed=0, **params):
        where = f"brume.transforms.{type(self).__name__}()"
        super().__init__(p, seed)
        self._stage = _Stage(_COMMANDS[self._commands[0]], params, where)

    def draw(self, key):
        """Whether it applies, and the values: the sampler's draw plus the
        noise's seed, 53 bits of the same hash scheme (name "noise-seed")."""
        if not self._applies(key):
            return False, {}
        values = self._stage.draw(self.seed, key)
        values["seed"] = self._noise_seed(key)
        return True, values

    def __call__(self, points=None, key=None, **targets):
        if points is None:
            raise ValueError("points: call t(points=...) with an (N, 4) float32 array of x, y, z, intensity")
        key = self._auto_key() if key is None else str(key)
        applied, values = self.draw(key)
        out, record = self._apply(points, values) if applied else (points, None)
        params = {"values": values, "applied": applied, "seed": self.seed, "key": key, "record": record}
        return dict(targets, points=out, params=params)

    def _apply(self, points, values, job=None):
        pts = _Points(points, "points")
        f = self._stage.function
        r = f(pts.array, job=job) if job is not None else f(pts.array, **self._stage.fixed, **values)
        return pts.back(r.points), r.record

    def replay(self, params):
        """replay(params)(points=...) repeats the sample bit for bit."""
        self._check_params(params)

        def again(points=None, **targets):
            if not params["applied"]:
                return dict(targets, points=points, params=params)
            out, _ = self._apply(points, None, job=params["record"]["job"])
            return dict(targets, points=out, params=params)

        return again

    def __repr__(self):
        return f"{type(self).__name__}(p={self.p}, seed={self.seed}, {json.dumps(self._stage.specs)})"


def _class_name(command):
    """Haze, Aerial, Fog, DepthOfField; a chain haze+dof: HazeThenDof."""
    parts = command.split("+")
    if len(parts) == 1:
        return {"dof": "DepthOfField"}.get(command, command.title().replace(" ", ""))
    return "Then".join(p.title() for p in parts)


def _make_classes():
    made = {}
    for c in _COMMANDS.values():
        if c["sampling"] and c["arrays"] == ["points"]:  # a LiDAR effect (the LiDAR fog)
            doc = (f"{c['summary']}.\n\nAs a transform on a scan: every parameter of `brume sample {c['name']}` "
                   "takes a fixed value, a (lo, hi) tuple (uniform), loguniform(lo, hi) or choice(...); "
                   "see docs/transforms.md.")
            made[_class_name(c["name"])] = type(_class_name(c["name"]), (PointsTransform,),
                                                {"_commands": (c["name"],), "__doc__": doc})
            continue
        stages = c["name"].split("+")
        ok = all(s in _COMMANDS and _COMMANDS[s]["sampling"] and _COMMANDS[s]["arrays"] == ["rgb", "range"]
                 for s in stages)
        if not ok or (len(stages) > 1 and not c["stage_prefix"]):
            continue
        prefixes = tuple(c["stage_prefix"].replace("-", "_") for _ in stages[1:])
        doc = (f"{c['summary']}.\n\nAs a transform: every parameter of `brume sample {stages[0]}`"
               + (f" (the later stage's with the prefix {prefixes[0]!r})" if prefixes else "")
               + " takes a fixed value, a (lo, hi) tuple (uniform), loguniform(lo, hi) or choice(...); "
                 "see docs/transforms.md.")
        made[_class_name(c["name"])] = type(_class_name(c["name"]), (Transform,),
                                            {"_commands": tuple(stages), "_prefixes": prefixes, "__doc__": doc})
    return made


_CLASSES = _make_classes()
globals().update(_CLASSES)
__all__ += sorted(_CLASSES)
