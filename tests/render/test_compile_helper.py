"""The two-process cold compile (anim/render/compile_helper.py, issue 21):
the helper compiles the surface half on made-up camera hits and a made-up
shadow BVH, so these must have exactly the numba types of the real ones,
or the main process would compile every surface kernel again (the wheel
test checks that end to end on a really cold cache). A failing helper
costs nothing but time."""
import numba
import numpy as np
import pytest

from anim.render import compile_helper
from anim.render.renderer import SceneRenderer
from anim.render.settings import config_of, shading_of
from anim.scene import AnimatedScene
from raycore.geometry.camera import camera_basis
from raycore.frame import Geometry
from tests.conftest import ROOT

DEMO = ROOT / "anim" / "builtin" / "demo" / "anim.yaml"


def _types(values):
    return [numba.typeof(v) for v in values]


@pytest.fixture(scope="module")
def demo_structures():
    scene = AnimatedScene(DEMO)
    cfg = config_of(scene, width=64, height=48)
    renderer = SceneRenderer(scene, cfg, shading_of(scene))
    geom = Geometry(scene.vertices_at(0.0), scene.faces, scene.tri_material, scene.uvs, *renderer.vf)
    tri_verts, built = renderer.structures.build({"grid", "kdtree", "bvh"}, geom, cfg, renderer.buffers, {})
    return scene, cfg, tri_verts, built, renderer.buffers


@pytest.mark.parametrize("accel", ["grid", "kdtree", "bvh"])
def test_made_up_camera_hits_have_the_types_of_every_structures_hits(demo_structures, accel):
    scene, cfg, tri_verts, built, _ = demo_structures
    cam = camera_basis((0, 1, 6), (0, 0, 0), (0, 1, 0), 40.0, cfg.width, cfg.height)
    made_up = compile_helper.MadeUpHits(scene.faces.shape[0])
    real, real_layout = built[accel].trace_camera(cam, cfg.width, cfg.height, (0.5, 0.5))
    fake, fake_layout = made_up.trace_camera(cam, cfg.width, cfg.height, (0.5, 0.5))
    assert _types(fake[:4]) == _types(real[:4]) and _types(fake_layout) == _types(real_layout)
    assert type(fake.counters) is type(real.counters)
    # every made-up ray hits a triangle, so that every surface kernel runs
    assert (fake.prim >= 0).all() and fake.prim.max() < scene.faces.shape[0]
    origins = np.zeros((10, 3), np.float32)
    dirs = np.tile(np.float32([0, 0, -1]), (10, 1))
    assert _types(made_up.trace_rays(origins, dirs)[:4]) == _types(built[accel].trace_rays(origins, dirs)[:4])


def test_the_made_up_shadow_bvh_has_the_types_of_a_built_one_and_traces(demo_structures):
    _, _, tri_verts, built, buffers = demo_structures
    made_up = compile_helper.made_up_bvh(tri_verts, buffers.work)
    assert numba.typeof(made_up.bvh) == numba.typeof(built["bvh"].bvh)
    origins = np.tile(np.float32([0, 5, 0]), (4, 1))
    dirs = np.tile(np.float32([0, -1, 0]), (4, 1))
    hits = made_up.trace_rays(origins, dirs)          # a valid tree: traversal runs on it
    assert hits.prim.shape == (4,)


def test_no_helper_when_switched_off_or_when_the_cache_is_warm(monkeypatch, demo_structures):
    monkeypatch.setenv("FRUSTRACE_COMPILE_HELPER", "0")
    assert not compile_helper.wanted()
    monkeypatch.setenv("FRUSTRACE_COMPILE_HELPER", "1")
    monkeypatch.setattr(compile_helper, "_cached", lambda probe: True)
    assert not compile_helper.wanted()


def test_a_failing_helper_reports_nothing_and_the_render_goes_on(tmp_path):
    class Missing:
        path = tmp_path / "no_such_scene.yaml"
        camera_choice = None
    helper = compile_helper.Helper(Missing(), None, 0.0)
    assert helper.finish() == {}
    assert helper.proc.returncode != 0
