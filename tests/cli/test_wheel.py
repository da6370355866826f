"""The installable artefact (issue 21): `make wheel`'s dist/frustrace-*.whl,
installed into a fresh virtual environment outside the source tree, renders
the demo from there with nothing of the source tree on its path. The new
environment takes its dependencies from the test's own environment (a .pth
line to its site-packages, whose own .pth files, the editable install's
among them, are not processed), so the test needs no network.

The installed copy's numba cache is seeded from the source tree's (the
files are the same bytes, and numba keys its cache by their hash), so
that the test does not pay a second cold compile of the demo (42 s of CPU,
a fifth of the suite's); that it compiles nothing checks that an installed
copy finds its cache. The two-process cold compile itself is checked on the
suite's own cold start (conftest.py), which every fresh clone and CI run
has: test_a_cold_start_compiles_in_two_processes."""
import json
import os
import shutil
import site
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import pytest

from tests.conftest import COLD_START

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("anim", "cli", "raycore")


def seed_numba_cache(site_dir: Path):
    """Copy the source tree's numba cache files next to the installed copy's
    sources: numba's cache index is keyed by a hash of the source's bytes,
    which the wheel keeps. The tree's cache is first brought up to date for
    the demo by rendering it in the tree (1-2 s when current): conftest's
    cold start only runs when its probe kernels are missing, so after an
    edit to another kernel the tree's entry would be stale, and so would
    the copy."""
    with tempfile.TemporaryDirectory() as out:
        subprocess.run([sys.executable, "-m", "cli.main", "render", str(ROOT / "anim/builtin/demo/anim.yaml"),
                        "-o", out, "--frames", "0:0", "--res", "16x16", "-q"],
                       cwd=ROOT, check=True, capture_output=True, timeout=900)
    for package in PACKAGES:
        for cache in (ROOT / package).rglob("__pycache__"):
            target = site_dir / cache.relative_to(ROOT)
            for f in cache.glob("*.nb[ic]"):
                target.mkdir(parents=True, exist_ok=True)
                shutil.copy2(f, target / f.name)


def test_the_wheel_installs_and_renders_the_demo_outside_the_tree(tmp_path):
    dist = tmp_path / "dist"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(dist),
                    str(ROOT)], check=True, cwd=tmp_path, timeout=600, capture_output=True)
    wheels = list(dist.glob("frustrace-*.whl"))
    assert len(wheels) == 1
    names = zipfile.ZipFile(wheels[0]).namelist()
    assert "anim/builtin/demo/anim.yaml" in names and "anim/builtin/demo/checker.png" in names
    assert not any(n.startswith("tests/") for n in names)
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=300)
    python = venv / "bin" / "python"
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "-q",
                    str(wheels[0])], check=True, timeout=600, capture_output=True)
    new_site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                   check=True, capture_output=True, text=True).stdout.strip())
    (new_site / "_deps_from_test_env.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    seed_numba_cache(new_site)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    work = tmp_path / "work"
    work.mkdir()
    where = subprocess.run([str(python), "-c", "import cli, raycore; print(cli.__file__); print(raycore.__file__)"],
                           check=True, capture_output=True, text=True, cwd=work, env=env).stdout.split()
    assert all(Path(w).is_relative_to(venv) for w in where), where          # the wheel's copy, not the tree's
    frustrace = str(venv / "bin" / "frustrace")
    run = lambda *args: subprocess.run([frustrace, *args], capture_output=True, text=True, cwd=work, env=env,
                                       timeout=900)
    made = run("assets", "make", "demo", "-o", "demo")
    assert made.returncode == 0, made.stderr
    out = run("render", "demo/anim.yaml", "-o", "frames", "--frames", "0:1", "--res", "32x24", "-q")
    assert out.returncode == 0, out.stderr
    assert sorted(p.name for p in (work / "frames").glob("*.exr")) == ["frame_0000.exr", "frame_0001.exr"]
    # the installed copy found the seeded cache: no kernel compiled, no helper started
    run_stats = json.loads((work / "frames" / "stats.json").read_text())["runs"][-1]
    assert run_stats["compiled"] == {} and not run_stats.get("compiled_by_helper"), run_stats


def test_a_cold_start_compiles_in_two_processes():
    """The suite's cold start (conftest.py: the demo rendered on a cold
    cache, as on a fresh clone): a helper process compiled the surface half
    (anim/render/compile_helper.py) with the very specialisations the frames
    use, so the render's own process compiled none of them."""
    stats = COLD_START / "stats.json"
    if not stats.exists():
        pytest.skip("the suite started on a warm numba cache (a fresh clone, as in CI, starts cold)")
    assert sorted(p.name for p in COLD_START.glob("*.exr")) == ["frame_0000.exr", "frame_0001.exr"]
    run_stats = json.loads(stats.read_text())["runs"][-1]
    here, helper = set(run_stats["compiled"]), set(run_stats.get("compiled_by_helper", {}))
    # the sweep (raycore/sweep.py), with the stages it calls compiled
    # inside it (the watch lists top-level compiles), which nothing here compiled
    # and the shadow rays' packet walk, which it calls through its address
    surface_half = {"raycore.sweep.shade_blocks", "raycore.bvh.trace.trace_block_lights_into"}
    stages = {"raycore.shading.surface.fill_block", "raycore.shading.shade.shade_rows", "raycore.shading.shade.write_block"}
    assert {"raycore.grid.drivers.trace_primary", "raycore.bvh.build._build_nodes"} <= here
    assert surface_half <= helper and not (surface_half | stages) & here, (here, helper)
    assert "raycore.bvh.build._build_nodes" not in helper            # the helper's BVH is made up
    # the demo takes the sweep: the phase by phase path is compiled nowhere
    phase_by_phase = {"raycore.shading.surface.fill_surface", "raycore.shading.shade.shade_samples",
                      "raycore.shading.shade.write_pixels", "raycore.bvh.trace.trace_light_samples"}
    assert not phase_by_phase & (here | helper), (here, helper)
