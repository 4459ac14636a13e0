"""Shared fixtures of the Python tests: the CLI built beside the module, a
small demo scene, a synthetic LiDAR scan, the real data folder, and the GPU
gate."""
import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


def cli_path():
    p = os.environ.get("BRUME_CLI") or str(ROOT / "build" / "brume")
    if not os.path.exists(p):
        pytest.skip(f"the brume CLI is not built ({p}); build target brume_cli or set BRUME_CLI")
    return p


def run_cli(*args, cwd=None):
    """Runs `brume ARGS` and fails the test with its stderr when it fails."""
    r = subprocess.run([cli_path(), *map(str, args)], capture_output=True, text=True, cwd=cwd)
    assert r.returncode == 0, f"brume {' '.join(map(str, args))} failed ({r.returncode}):\n{r.stderr}"
    return r


def scan(n=4000, seed=2):
    """A synthetic LiDAR scan, (N, 4) float32: points on random beams at
    1.5-90 m (the far ones turn into fog at a visibility of tens of metres),
    reflectance in [0, 1] as KITTI's."""
    import numpy as np
    g = np.random.default_rng(seed)
    d = g.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = g.uniform(1.5, 90.0, size=(n, 1))
    return np.hstack([d * r, g.uniform(0, 1, size=(n, 1))]).astype(np.float32)


@pytest.fixture(scope="session")
def demo(tmp_path_factory):
    """The procedural demo scene at 160 x 112: clean.png (8-bit sRGB) and
    range.exr (metres, NaN sky), plus the arrays brume reads from them."""
    import brume
    d = tmp_path_factory.mktemp("demo")
    run_cli("demo", "--out-dir", d, "--width", 160, "--height", 112)
    rgb = brume.read_image(d / "clean.png").rgb
    rng = brume.depth.convert(range=d / "range.exr").range
    return {"dir": d, "rgb": rgb, "range": rng}


DATA_WHERE = "BRUME_DATA_DIR, else ../shared/data beside the repository"


def data_folder():
    """The real data folder: the environment variable BRUME_DATA_DIR when it
    is set and not empty, else ../shared/data beside the repository (as the
    C++ tests' data_path)."""
    return pathlib.Path(os.environ.get("BRUME_DATA_DIR") or (ROOT.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def data_dir():
    """The real data folder; the test skips when it is absent or empty. A test
    that reads the data requests this fixture (that puts its file under the
    ctest label `data`, python/CMakeLists.txt) and checks what it reads with
    require_data."""
    d = data_folder()
    if not d.is_dir() or not any(d.iterdir()):
        pytest.skip(f"the real data folder {d} is absent or empty ({DATA_WHERE})")
    return d


def require_data(path):
    """path, a file or folder of the data; the test skips when it is absent."""
    if not os.path.exists(path):
        pytest.skip(f"real data {path} is absent: the data folder ({DATA_WHERE}) does not hold it")
    return path


@pytest.fixture(scope="session")
def gpu():
    """Skips GPU tests when no EGL/GLES 3.2 context can be made, unless
    BRUME_REQUIRE_GPU=1, which turns that into a failure."""
    import numpy as np
    import brume
    try:
        brume.blur(np.zeros((4, 4, 3), np.float32), sigma=1.5, backend="gpu")
    except RuntimeError as e:
        if os.environ.get("BRUME_REQUIRE_GPU") == "1":
            pytest.fail(f"BRUME_REQUIRE_GPU=1 but no GPU context: {e}")
        pytest.skip(f"no GPU context: {e}")
    return True


def assert_gil_released(call, what):
    """Runs call() while a Python thread counts. Held GIL: the counter gets
    nothing until the call returns (a few ticks at most around the switch).
    Released: it counts the whole time (millions per second in CPython 3.11;
    10^4 per second is a safe floor). The call must take over 50 ms to tell."""
    import threading
    import time
    ticks, running = [0], [True]

    def count():
        while running[0]:
            ticks[0] += 1

    t = threading.Thread(target=count)
    t.start()
    time.sleep(0.05)
    before = ticks[0]
    t0 = time.perf_counter()
    call()
    elapsed = time.perf_counter() - t0
    during = ticks[0] - before
    running[0] = False
    t.join()
    assert elapsed > 0.05, f"the {what} was too short to tell"
    assert during > 1e4 * elapsed, f"{during} ticks in {elapsed:.3f} s: the GIL was held"
