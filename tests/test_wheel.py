"""The installable artefact (issue 21): `make wheel`'s dist/frustrace-*.whl,
installed into a fresh virtual environment outside the source tree, renders
the demo from there with nothing of the source tree on its path. The new
environment takes its dependencies from the test's own environment (a .pth
line to its site-packages, whose own .pth files, the editable install's
among them, are not processed), so the test needs no network. Its cache
is cold, so it also checks the two-process cold compile."""
import json
import os
import site
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


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
    # the installed copy's cache was cold: a helper process compiled the
    # surface half (anim/render/compile_helper.py) with the very
    # specialisations the frames use, so this process compiled none of them
    run_stats = json.loads((work / "frames" / "stats.json").read_text())["runs"][-1]
    here, helper = set(run_stats["compiled"]), set(run_stats.get("compiled_by_helper", {}))
    surface_half = {"raycore.surface.fill_surface", "raycore.shade.shade_samples",
                    "raycore.shadow_rays.light_space_order", "raycore.bvh_trace.trace_batch"}
    assert {"raycore.grid_drivers.trace_primary", "raycore.bvh_build.build_region"} <= here
    assert surface_half <= helper and not surface_half & here, (here, helper)
    assert "raycore.bvh_build.build_region" not in helper            # the helper's BVH is made up
    # this process's made-up scatter (no samples) had the real call's types
    assert "raycore.shade.write_pixels" in here and "raycore.shade.write_pixels" not in helper
