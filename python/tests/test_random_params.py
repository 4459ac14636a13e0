"""brume.random_params: the library's sampler seen from Python (issue #14
item 3) -- the same values as `brume sample`, in range, reproducible, keyed by
(seed, key, name) and never by call order; bad specs raise ValueError."""
import hashlib
import json
import math

import numpy as np
import pytest

import brume
from conftest import run_cli


def unit(seed, key, name):
    """The documented hash (README, brume-sample-v1), computed independently."""
    d = hashlib.sha256(b"brume-sample-v1\0" + str(seed).encode() + b"\0" + key.encode() + b"\0" +
                       name.encode()).digest()
    return (int.from_bytes(d[:8], "big") >> 11) / 2.0 ** 53


def test_same_values_as_the_cli_and_the_documented_hash():
    p = brume.random_params("haze", 7, "Art/view1.png")
    cli = json.loads(run_cli("sample", "--effect", "haze", "--seed", 7, "--key", "Art/view1.png").stdout)
    assert p == cli["params"]  # the same doubles, to the last bit
    # visibility = loguniform(50, 5000) at u: exp(ln 50 + u (ln 5000 - ln 50)), to double rounding.
    u = unit(7, "Art/view1.png", "visibility")
    assert p["visibility"] == pytest.approx(math.exp(math.log(50) + u * (math.log(5000) - math.log(50))), rel=1e-12)


def test_ranges_override_and_are_respected():
    for k in range(200):
        p = brume.random_params("haze", 3, f"frame{k}", visibility="loguniform(8, 80)", albedo=0.9,
                                lambda_=[1, 2, 4])
        assert 8 <= p["visibility"] < 80
        assert p["albedo"] == 0.9
        assert p["lambda"] in (1, 2, 4)


def test_keyed_not_ordered():
    a = [brume.random_params("fog", 11, f"k{i}") for i in range(20)]
    b = [brume.random_params("fog", 11, f"k{i}") for i in reversed(range(20))][::-1]
    assert a == b
    assert brume.random_params("fog", 11, "k0") != brume.random_params("fog", 12, "k0")
    # A parameter's draw does not depend on which others are drawn.
    assert (brume.random_params("haze", 5, "x", lambda_=0.0)["visibility"] ==
            brume.random_params("haze", 5, "x")["visibility"])


def test_the_dict_feeds_the_effect(tmp_path):
    rgb = np.full((24, 32, 3), 0.5, np.float32)
    rng = np.linspace(1, 40, 24 * 32, dtype=np.float32).reshape(24, 32)
    p = brume.random_params("haze", 1, "f")
    r = brume.haze(rgb, rng, **p)
    assert r.record["job"]["haze"]["visibility"] == p["visibility"]


def test_bad_ranges_raise():
    with pytest.raises(ValueError, match="albedo"):
        brume.random_params("haze", 1, "f", albedo="uniform(-1, 1)")
    with pytest.raises(ValueError, match="visiblity|visibility"):
        brume.random_params("haze", 1, "f", visiblity="uniform(1, 2)")
    with pytest.raises(ValueError):
        brume.random_params("nosuch", 1, "f")
    with pytest.raises(TypeError, match="visibility"):
        brume.random_params("haze", 1, "f", visibility={"a": 1})
