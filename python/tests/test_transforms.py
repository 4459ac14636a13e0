"""brume.transforms and the module in forked workers (issue #42): fork safety,
the albumentations call protocol, types, determinism, replay against the CLI,
clips, bad arguments."""
import multiprocessing

import numpy as np
import pytest

import brume

# A forked child that hangs fails its test after this long instead of hanging
# ctest: the effects below take milliseconds (64 x 48 pixels).
FORK_TIMEOUT_S = 60


def _scene(h=48, w=64, seed=0):
    g = np.random.default_rng(seed)
    rgb = g.random((h, w, 3), dtype=np.float32)
    yy, xx = np.mgrid[0:h, 0:w]
    rng = (20.0 + 3.0 * xx + 0.5 * yy).astype(np.float32)
    return rgb, rng


# ---- fork safety (item 5) -------------------------------------------------------------------
def _child_haze(threads):
    rgb, rng = _scene()
    kw = {} if threads is None else {"threads": threads}
    return brume._brume._in_forked_child(), brume.haze(rgb, rng, visibility=300, **kw).rgb


def test_forked_pool_runs_effects_after_the_parent_ran_one():
    """The parent opens libgomp's pool (threads=2), then forks a Pool whose
    workers run effects: with the default threads (one thread in a forked
    child) and with threads=2 asked for (a thread of its own, fresh pool).
    Without the fork handling the workers wait forever on the parent's pool;
    the timeout turns that into a failure. Results equal the parent's bits
    (results do not depend on threads)."""
    rgb, rng = _scene()
    parent = brume.haze(rgb, rng, visibility=300, threads=2).rgb
    assert not brume._brume._in_forked_child()
    with multiprocessing.get_context("fork").Pool(2) as pool:
        got = pool.map_async(_child_haze, [None, 2, None, 2, 1]).get(timeout=FORK_TIMEOUT_S)
    for forked, child in got:
        assert forked
        np.testing.assert_array_equal(child, parent)
