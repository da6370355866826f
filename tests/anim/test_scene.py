"""Scene evaluation: TRS transforms, animated camera, static objects, spp."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from anim.scene import AnimatedScene
from anim.errors import SceneError
from raycore.config import RenderConfig
from anim.render.renderer import SceneRenderer
from anim.render.settings import shading_of

from scene_files import DEMO, scene_with  # noqa: F401  (DEMO: other tests take it from here too)


def test_trs_maps_v_to_t_plus_r_of_s_times_v(tmp_path):
    path = scene_with(tmp_path, """  - name: ball
    mesh: ball.obj
    transform:
      translation: {keys: [[0, 1, 2, 3], [2, 3, 2, 1]]}
      rotation: {keys: [[0, 1, 0, 0, 0], [2, 0.7071068, 0, 0.7071068, 0]]}
      scale: {keys: [[0, 1, 2, 0.5]]}""")
    scene = AnimatedScene(path)
    base = scene.objects[0].base.astype(np.float64)
    t = 0.5
    trans = np.array([1, 2, 3]) + (np.array([3, 2, 1]) - np.array([1, 2, 3])) * (t / 2)
    rot = Rotation.from_euler("y", 90 * t / 2, degrees=True).as_matrix()
    expected = (base * np.array([1, 2, 0.5])) @ rot.T + trans
    np.testing.assert_allclose(scene.vertices_at(t), expected, atol=1e-5)
    assert not scene.objects[0].static and scene.objects[0].rigid


def test_static_objects_are_placed_once_and_never_rewritten(tmp_path):
    path = scene_with(tmp_path, """  - name: floor
    mesh: floor.obj
  - name: tube
    keyframes:
      - {t: 0, mesh: tube_000.obj}
      - {t: 1, mesh: tube_001.obj}
  - name: still
    keyframes:
      - {t: 0, mesh: tube_000.obj}""")
    scene = AnimatedScene(path)
    assert [o.name for o in scene.moving] == ["tube"]
    floor = scene.objects[0]
    before = scene.vertices[floor.offset:floor.offset + len(floor.base)].copy()
    scene.vertices[floor.offset] = 123.0              # a write here would be undone if re-placed
    scene.vertices_at(0.7)
    assert scene.vertices[floor.offset, 0] == 123.0
    assert np.array_equal(before[1:], scene.vertices[floor.offset + 1:floor.offset + len(floor.base)])


def test_animated_camera_follows_its_keys(tmp_path):
    path = scene_with(tmp_path, "  - {name: floor, mesh: floor.obj}",
                      camera_yaml="""camera:
  interpolation: linear
  keys:
    - {t: 0, eye: [0, 1, 6], look_at: [0, 0, 0], fov: 30}
    - {t: 2, eye: [4, 1, 6], look_at: [0, 0, 0], fov: 50}""")
    scene = AnimatedScene(path)
    eye, look_at, up, fov = scene.camera_at(1.0)
    np.testing.assert_allclose(eye, [2, 1, 6])
    assert abs(fov - 40) < 1e-9 and tuple(up) == (0, 1, 0)
    eye, *_ = scene.camera_at(5.0)                         # clamped after the last key
    np.testing.assert_allclose(eye, [4, 1, 6])


def test_directional_light_needs_a_direction(tmp_path):
    path = scene_with(tmp_path, "  - {name: floor, mesh: floor.obj}")
    path.write_text(path.read_text().replace("lights: [{type: point, position: [3, 5, 4], intensity: 30}]",
                                             "lights: [{type: directional, position: [3, 5, 4]}]"))
    with pytest.raises(SceneError, match="lights.0"):
        AnimatedScene(path)


def render(scene, spp, shadows=True, aovs=()):
    w, h = scene.spec.output.resolution
    cfg = RenderConfig(width=w, height=h, packet=8, spp=spp, shadows=shadows, aovs=aovs)
    return SceneRenderer(scene, cfg, shading_of(scene)).render(0.0)[1]


def test_supersampling_averages_coverage_and_keeps_nearest_depth(tmp_path):
    path = scene_with(tmp_path, "  - {name: ball, mesh: ball.obj}")
    scene = AnimatedScene(path)
    one, four = render(scene, 1), render(scene, 4)
    a1, a4 = one.rgba[..., 3], four.rgba[..., 3]
    assert set(np.unique(a1)) <= {0.0, 1.0}
    edge = (a4 > 0) & (a4 < 1)
    assert edge.any()                                      # partial coverage on the silhouette
    assert np.all(np.isfinite(four.z[a4 > 0])) and np.all(np.isinf(four.z[a4 == 0]))
    # Z is the nearest of the samples: trace each sample alone and compare
    from oracles import kernel_camera_rays
    from raycore.geometry.camera import camera_basis
    from raycore.geometry.sampling import sample_offsets
    from raycore.grid.build import build_grid
    from raycore.grid.trace import trace_camera
    w, h = scene.spec.output.resolution
    tv = np.ascontiguousarray(scene.vertices_at(0.0)[scene.faces].reshape(-1, 9), np.float32)
    grid = build_grid(tv)
    eye, look_at, up, fov = scene.camera_at(0.0)
    cam = camera_basis(eye, look_at, up, fov, w, h)
    zs = []
    for jx, jy in sample_offsets(4):
        hits = trace_camera(grid, tv, cam, w, h, 8, (jx, jy))
        _, d = kernel_camera_rays(cam, w, h, np.float32(jx), np.float32(jy))
        zs.append(np.where(hits.prim >= 0, hits.t * (d @ cam[3:6]), np.inf))
    np.testing.assert_allclose(four.z.ravel(), np.min(zs, axis=0), rtol=1e-6)


def test_shadows_off_and_no_lights_leave_out_the_shadow_pass(tmp_path):
    path = scene_with(tmp_path, """  - {name: floor, mesh: floor.obj}
  - name: ball
    mesh: ball.obj
    transform: {translation: {keys: [[0, 0.3, 0.8, 0.6]]}}""")
    scene = AnimatedScene(path)
    lit = render(scene, 1, shadows=True)
    unlit = render(scene, 1, shadows=False)
    assert lit.counters["shadow_rays"] > 0 and unlit.counters["shadow_rays"] == 0
    assert lit.rgba[..., :3].sum() < unlit.rgba[..., :3].sum()   # the ball casts a shadow


SPEC_EXAMPLE = """
version: 1
frames: {start: 0, end: 47, fps: 24}        # frame f is rendered at t = f / fps
output: {path: out/frame_####.exr, resolution: [1024, 1024], aovs: [N]}
camera: {eye: [0, 1.5, 6], look_at: [0, 0.8, 0], up: [0, 1, 0], fov: 40}
render: {accel: grid, packet: 8, shadows: true, spp: 1, background: [0.02, 0.02, 0.03]}
lights:
  - {type: point, position: [4, 6, 5], color: [1, 1, 1], intensity: 60}
  - {type: area, corner: [-1, 5, -1], edge_u: [2, 0, 0], edge_v: [0, 0, 2],   # rectangle
     color: [1, 1, 1], intensity: 60, samples: 16}                           # soft shadows
materials:
  skin: {diffuse: [0.8, 0.6, 0.5], specular: 0.1, shininess: 32, texture: skin.png}
objects:
  - name: hand                      # deforming mesh: vertex-position keyframes
    material: skin
    interpolation: catmull-rom      # linear | catmull-rom | cubic
    extrapolate: clamp              # clamp | loop
    keyframes:
      - {t: 0.0, mesh: hand/key_000.obj}
      - {t: 0.5, mesh: hand/key_001.obj}
  - name: marble                    # rigid mesh moved by TRS tracks
    mesh: sphere.obj
    transform:
      translation: {interpolation: catmull-rom, keys: [[0.0, 0, 1, 0], [1.0, 2, 1, 0]]}
      rotation:    {keys: [[0.0, 1, 0, 0, 0], [1.0, 0, 0, 1, 0]]}   # t, w, x, y, z; slerp
      scale:       {keys: [[0.0, 1, 1, 1]]}
"""


def test_the_spec_example_still_validates():
    """The schema extensions (skeletons, glTF, more methods) stay backward compatible."""
    import yaml
    from anim.schema import parse_scene
    spec = parse_scene(yaml.safe_load(SPEC_EXAMPLE))
    assert spec.objects[0].interpolation == "catmull-rom" and spec.objects[1].transform.rotation is not None


def test_aovs_of_a_multisample_pixel_are_its_nearest_hit(tmp_path):
    """With spp > 1, id, N and P come from the sample whose depth Z reports:
    every pixel with coverage A > 0 has an id, a unit normal and a position
    at depth Z; an uncovered pixel has id -1 and zeros."""
    path = scene_with(tmp_path, "  - {name: ball, mesh: ball.obj}\n  - {name: floor, mesh: floor.obj}")
    scene = AnimatedScene(path)
    w, h = scene.spec.output.resolution
    cfg = RenderConfig(width=w, height=h, spp=4, aovs=("N", "P", "id"))
    out = SceneRenderer(scene, cfg, shading_of(scene)).render(0.0)[1]
    a, z = out.rgba[..., 3], out.z
    covered = a > 0
    assert ((a > 0) & (a < 1)).sum() > 10                  # partly covered edge pixels exist
    assert np.all(out.aovs["id"][covered] >= 0) and np.all(out.aovs["id"][~covered] == -1)
    n = np.stack([out.aovs[f"N.{c}"] for c in "XYZ"], -1)
    np.testing.assert_allclose(np.linalg.norm(n[covered], axis=-1), 1, atol=1e-4)
    assert np.all(n[~covered] == 0)
    p = np.stack([out.aovs[f"P.{c}"] for c in "XYZ"], -1)
    from raycore.geometry.camera import camera_basis
    eye, look_at, up, fov = scene.camera_at(0.0)
    cam = camera_basis(eye, look_at, up, fov, w, h)
    depth = (p - cam[:3]) @ cam[3:6]                       # P's distance along the view axis
    np.testing.assert_allclose(depth[covered], z[covered], rtol=1e-4)
