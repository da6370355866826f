"""Built-in scenes: sizes of the classic scenes, byte-identical regeneration,
exact motion that the written scene reproduces at its keys, and a render."""
import filecmp
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from anim import builtin
from anim.scene import AnimatedScene
from cli.main import main

CLASSIC = ["hand", "runner", "toys", "marbles", "fairy"]


def _files(root):
    return sorted(p.relative_to(root) for p in Path(root).rglob("*") if p.is_file())


@pytest.mark.parametrize("name", CLASSIC)
def test_triangle_count_is_within_10_percent_of_the_classic_scene(name):
    scene = builtin.get(name)
    assert abs(scene.triangles - scene.target_triangles) <= 0.1 * scene.target_triangles


@pytest.mark.parametrize("name", CLASSIC + ["field"])
def test_generation_is_deterministic(name, tmp_path):
    a = builtin.get(name).write(tmp_path / "a")
    b = builtin.get(name).write(tmp_path / "b")
    files = _files(a.parent)
    assert files == _files(b.parent) and len(files) > 2
    match, mismatch, errors = filecmp.cmpfiles(a.parent, b.parent, [str(f) for f in files], shallow=False)
    assert not mismatch and not errors


@pytest.mark.parametrize("name", CLASSIC + ["torus", "field"])
def test_written_scene_reproduces_the_exact_motion_at_its_keys(name, tmp_path):
    gen = builtin.get(name)
    scene = AnimatedScene(gen.write(tmp_path / name))
    assert scene.faces.shape[0] == gen.triangles and not scene.warnings
    size = np.ptp(gen.exact(0.0), axis=0).max()
    keyed = [p for p in gen.parts if p.moving]
    key_times = keyed[0].key_times
    for t in key_times[[0, 1, len(key_times) // 2, -1]]:
        err = np.abs(scene.vertices_at(t).astype(np.float64) - gen.exact(t)).max()
        assert err < 4e-6 * max(size, 1.0), (t, err)
    # between keys: interpolation error only, small against the scene
    for t in key_times[:3] + 0.37 * np.diff(key_times[:4]):
        err = np.abs(scene.vertices_at(t).astype(np.float64) - gen.exact(t)).max()
        assert 0 < err < 0.05 * size, (t, err)


@pytest.mark.parametrize("name", CLASSIC)
def test_scene_renders(name, tmp_path):
    from anim.render.renderer import SceneRenderer
    from anim.render.settings import config_of, shading_of
    scene = AnimatedScene(builtin.get(name).write(tmp_path / name))
    cfg = config_of(scene, width=64, height=64, packet=8, spp=1, aovs=())
    _, result = SceneRenderer(scene, cfg, shading_of(scene)).render(scene.time_of(scene.frame_numbers[5]))
    assert np.all(np.isfinite(result.rgba))
    coverage = float(np.mean(result.rgba[..., 3]))
    assert coverage > 0.3, coverage
    assert result.counters["fallback_rays"] < 64 * 64


def test_fairy_takes_the_incremental_grid_path(tmp_path):
    from anim.render.renderer import SceneRenderer
    from anim.render.settings import config_of, shading_of
    scene = AnimatedScene(builtin.get("fairy").write(tmp_path / "fairy"))
    cfg = config_of(scene, width=32, height=32, packet=8)
    renderer = SceneRenderer(scene, cfg, shading_of(scene))
    assert renderer.structures.incremental
    assert len(scene.moving_triangles) < 0.02 * scene.faces.shape[0]


def test_assets_cli_lists_makes_and_rejects_unknown(tmp_path):
    res = CliRunner().invoke(main, ["assets", "list"])
    assert res.exit_code == 0 and all(n in res.output for n in CLASSIC)
    res = CliRunner().invoke(main, ["assets", "make", "toys", "-o", str(tmp_path / "t"),
                                    "--preview", str(tmp_path / "t.png")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "t" / "anim.yaml").is_file() and (tmp_path / "t.png").stat().st_size > 1000
    res = CliRunner().invoke(main, ["check", str(tmp_path / "t" / "anim.yaml")])
    assert res.exit_code == 0 and "11112 triangles" in res.output
    assert CliRunner().invoke(main, ["assets", "make", "nope"]).exit_code == 2
