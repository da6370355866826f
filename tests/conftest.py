import os
import sys
from pathlib import Path

# pytest-xdist runs a worker per core, each with numba's OpenMP threads: idle
# OpenMP threads spin (the default wait policy), taking the core the other
# worker needs. Passive waiting made the suite 1.4x faster (174 -> 121 s warm)
# and the error-budget bench test 5x (49 -> 10 s). Set before numba loads.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
# parsed meshes (anim/io/mesh_cache.py) kept with the suite's other caches, not
# in the user's ~/.cache; subprocesses inherit it
os.environ.setdefault("FRUSTRACE_CACHE_DIR", str(ROOT / ".pytest_cache" / "frustrace"))


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def soup(rng, n, spread=4.0, size=0.3):
    """Random triangle soup (n, 9) f32 in a cube of side `spread`."""
    centres = rng.random((n, 1, 3)) * spread - spread / 2
    tris = centres + rng.normal(size=(n, 3, 3)) * size
    return np.ascontiguousarray(tris.reshape(n, 9), np.float32)


def icosphere_mesh(level=2, radius=1.0):
    from anim.builtin.shapes import icosphere
    v, f = icosphere(level, radius)
    return v.astype(np.float32), f.astype(np.int32)


def tri_verts_of(vertices, faces):
    return np.ascontiguousarray(vertices[faces].reshape(-1, 9), np.float32)


# where the session's cold start leaves its render (tests/cli/test_wheel.py checks it)
COLD_START = ROOT / ".pytest_cache" / "cold_start"
# the controller's cold start is under way / has ended (the xdist workers wait for it)
COLD_START_RUNNING = ROOT / ".pytest_cache" / "cold_start.running"
COLD_START_DONE = ROOT / ".pytest_cache" / "cold_start.done"
COLD_START_WAIT_S = 900


def pytest_sessionstart(session):
    """On a cold numba cache, compile the demo's kernels once before the
    tests start: else every xdist worker compiles the same kernels at the
    same time. The render uses the two-process cold compile
    (anim/render/compile_helper.py); its frames and stats.json stay in
    COLD_START for the test of that compile (removed when the cache is warm).
    It runs in the background while the workers start and collect the
    tests (~3.5 s of CPU each, in the cold compile's idle moments); each
    worker then waits for COLD_START_DONE before its first test
    (pytest_collection_finish). This hook runs before xdist's, which starts
    the workers, so they always find COLD_START_RUNNING."""
    if hasattr(session.config, "workerinput"):        # an xdist worker: the controller did it
        return
    import shutil
    COLD_START_DONE.unlink(missing_ok=True)
    COLD_START.parent.mkdir(parents=True, exist_ok=True)
    COLD_START_RUNNING.touch()
    shutil.rmtree(COLD_START, ignore_errors=True)
    from anim.render import compile_helper
    if not compile_helper.wanted():
        COLD_START_DONE.touch()
        return
    import subprocess
    render = [sys.executable, "-m", "cli.main", "render", str(ROOT / "anim/builtin/demo/anim.yaml"),
              "-o", str(COLD_START), "--frames", "0:1", "--res", "64x64", "-q"]
    # the done file is written however the render ends (after a failed cold
    # start the tests compile what they need)
    script = ("import pathlib, subprocess\n"
              f"try:\n    subprocess.run({render!r}, cwd={str(ROOT)!r}, capture_output=True)\n"
              f"finally:\n    pathlib.Path({str(COLD_START_DONE)!r}).touch()\n")
    session.config._cold_start = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT, start_new_session=True)
    if not session.config.pluginmanager.hasplugin("dsession"):     # no workers: wait here
        session.config._cold_start.wait(timeout=COLD_START_WAIT_S)


def pytest_collection_finish(session):
    """An xdist worker, its tests collected: wait for the controller's cold start."""
    if not hasattr(session.config, "workerinput") or not COLD_START_RUNNING.exists():
        return
    import time
    deadline = time.monotonic() + COLD_START_WAIT_S
    while not COLD_START_DONE.exists() and time.monotonic() < deadline:
        time.sleep(0.05)


def pytest_sessionfinish(session):
    """The controller leaves no cold start behind (an interrupted run)."""
    proc = getattr(session.config, "_cold_start", None)
    if proc is not None and proc.poll() is None:
        import signal
        os.killpg(proc.pid, signal.SIGKILL)           # the render and its helper too
        proc.wait()


# the longest test files, longest first (pytest --durations): `make test` hands a whole file to a worker at a
# time (--dist loadfile), in collection order, so the long ones go first and
# the short ones fill in behind them, instead of one long file starting last
# while the other worker runs out of work
LONGEST_FILES = ("test_faults.py", "test_cluster.py", "test_exr_and_cli.py", "test_builtin_scenes.py",
                 "test_grid_cgt.py", "test_input_checks.py", "test_wheel.py")


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONGEST_FILES)))   # stable: files keep their order
