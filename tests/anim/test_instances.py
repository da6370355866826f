"""Instance tables (`instances:`, anim/instances.py): copies of an object
placed by their own TRS keys, against the same copies written as one
object each with translation, rotation and scale tracks (the TRS path of
anim/tracks.py, not the instance code); hidden copies collapse; the
prototype's own motion and materials come along; bad tables are one line
and exit 2."""
import numpy as np
import pytest
from click.testing import CliRunner

from cli.main import main

N, K = 9, 4
TIMES = [0.0, 0.3, 0.5, 1.0]


def _data(seed=5):
    rng = np.random.default_rng(seed)
    tr = rng.uniform(-3, 3, (K, N, 3))
    q = rng.normal(size=(K, N, 4))
    q /= np.linalg.norm(q, axis=2, keepdims=True)
    scale = rng.uniform(0.5, 1.5, (K, N, 3))
    return tr, q, scale


def _box(tmp_path):
    (tmp_path / "box.obj").write_text(
        "v -0.5 -0.5 -0.5\nv 0.5 -0.5 -0.5\nv 0.5 0.5 -0.5\nv -0.5 0.5 -0.5\n"
        "v -0.5 -0.5 0.5\nv 0.5 -0.5 0.5\nv 0.5 0.5 0.5\nv -0.5 0.5 0.5\n"
        "f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n")


HEAD = """version: 1
frames: {start: 0, end: 24, fps: 24}
output: {path: out/f_##.exr, resolution: [48, 48]}
camera: {eye: [0, 2, 12], look_at: [0, 0, 0], fov: 50}
lights: [{position: [3, 6, 4], intensity: 40}]
objects:
"""
OWN = "    transform: {rotation: {keys: [[0, 1, 0, 0, 0], [1, 0, 0, 1, 0]]}}\n"


def _rows(a):
    return "[" + ", ".join("[" + ", ".join(repr(float(x)) for x in row) + "]" for row in a) + "]"


def _instanced(tmp_path, tr, q, scale, extrapolate="clamp", inline=False, own=True):
    if inline:
        keys = "".join(f"        - {{t: {t}, translation: {_rows(tr[k])}, rotation: {_rows(q[k])}, "
                       f"scale: {_rows(scale[k])}}}\n" for k, t in enumerate(TIMES))
        inst = f"    instances:\n      interpolation: catmull-rom\n      keys:\n{keys}"
    else:
        np.savez(tmp_path / "field.npz", t=np.array(TIMES), translation=tr, rotation=q, scale=scale)
        inst = "    instances: {file: field.npz, interpolation: catmull-rom}\n"
    path = tmp_path / "inst.yaml"
    path.write_text(HEAD + f"  - name: boxes\n    mesh: box.obj\n    extrapolate: {extrapolate}\n"
                    + (OWN if own else "") + inst)
    return path


def _one_by_one(tmp_path, tr, q, scale, extrapolate="clamp"):
    """Copy i as its own object with TRS tracks (the keys of instance i)."""
    objects = ""
    for i in range(N):
        t_rows = [[float(t), *map(float, tr[k, i])] for k, t in enumerate(TIMES)]
        q_rows = [[float(t), *map(float, q[k, i])] for k, t in enumerate(TIMES)]
        s_rows = [[float(t), *map(float, scale[k, i])] for k, t in enumerate(TIMES)]
        objects += (f"  - name: c{i}\n    mesh: box.obj\n    extrapolate: {extrapolate}\n    transform:\n"
                    f"      translation: {{interpolation: catmull-rom, keys: {t_rows}}}\n"
                    f"      rotation: {{keys: {q_rows}}}\n"
                    f"      scale: {{interpolation: catmull-rom, keys: {s_rows}}}\n")
    path = tmp_path / "flat.yaml"
    path.write_text(HEAD + objects)
    return path


@pytest.mark.parametrize("extrapolate, inline", [("clamp", False), ("loop", True)])
def test_copies_are_placed_as_trs_tracks_place_objects(tmp_path, extrapolate, inline):
    """A still prototype: copy i equals object i of the same keys as TRS
    tracks, at key times, between them and past them (clamped or looped)."""
    from anim.scene import AnimatedScene
    _box(tmp_path)
    tr, q, scale = _data()
    inst = AnimatedScene(_instanced(tmp_path, tr, q, scale, extrapolate, inline, own=False))
    flat = AnimatedScene(_one_by_one(tmp_path, tr, q, scale, extrapolate))
    for t in (0.0, 0.13, 0.3, 0.42, 0.77, 1.0, 1.6):
        np.testing.assert_allclose(inst.vertices_at(t), flat.vertices_at(t), atol=1e-5)


def test_a_moving_prototype_is_placed_by_each_copy(tmp_path):
    """The prototype's own motion first, then the copy's T + R (S * p): at
    key times the copy's map is its keys exactly."""
    from anim.scene import AnimatedScene
    from anim.instances import quaternion_matrices
    _box(tmp_path)
    tr, q, scale = _data()
    scene = AnimatedScene(_instanced(tmp_path, tr, q, scale))
    obj = scene.objects[0]
    for k, t in enumerate(TIMES):
        own = np.empty((8, 3), np.float32)
        obj._place_one(t, own)                       # the box turning on its own track
        want = np.einsum("nij,nvj->nvi", quaternion_matrices(q[k]), own[None] * scale[k][:, None]) + tr[k][:, None]
        np.testing.assert_allclose(scene.vertices_at(t).reshape(N, 8, 3), want, atol=2e-6)
    assert not np.allclose(scene.vertices_at(0.0).reshape(N, 8, 3)[0] - tr[0, 0],
                           scene.vertices_at(1.0).reshape(N, 8, 3)[0] - tr[-1, 0])


def test_a_hidden_copy_collapses_and_the_table_must_fit(tmp_path):
    from anim.scene import AnimatedScene
    _box(tmp_path)
    tr, q, scale = _data()
    visible = np.ones((K, N), bool)
    visible[1, 4] = False
    np.savez(tmp_path / "field.npz", t=np.array(TIMES), translation=tr, rotation=q, scale=scale, visible=visible)
    path = tmp_path / "v.yaml"
    path.write_text(HEAD + "  - name: boxes\n    mesh: box.obj\n    instances: {file: field.npz}\n")
    scene = AnimatedScene(path)
    assert len(scene.faces) == N * 12
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 0 and f"boxes: {N * 12} triangles, {N} copies of 12 triangles, moving" in res.output
    v = scene.vertices_at(0.4).reshape(N, 8, 3)          # key 1 holds until key 2 (t = 0.5)
    assert np.all(v[4] == v[4][0]) and not np.all(v[3] == v[3][0])
    v = scene.vertices_at(0.5).reshape(N, 8, 3)
    assert not np.all(v[4] == v[4][0])


@pytest.mark.parametrize("table, words", [
    ("visible=np.ones((4, 8), bool)", "visible has shape (4, 8); expected (4, 9)"),
    ("scale=np.ones((4, 9, 2))", "scale has shape (4, 9, 2)"),
    ("translation=nan", "translation: inf or NaN (key 2, instance 5)"),
    ("rotation=zero", "rotation: a zero quaternion (key 0, instance 1)"),
    ("t=np.array([0.0, 0.5, 0.5, 1.0])", "key times must increase"),
    ("extra=np.ones(3)", "expected t, translation"),
])
def test_a_bad_instance_table_is_one_line_and_exit_2(tmp_path, table, words):
    _box(tmp_path)
    tr, q, scale = _data()
    arrays = {"t": np.array(TIMES), "translation": tr, "rotation": q, "scale": scale}
    name, expr = table.split("=", 1)
    if expr == "nan":
        tr = tr.copy()
        tr[2, 5, 1] = np.nan
        arrays["translation"] = tr
    elif expr == "zero":
        q = q.copy()
        q[0, 1] = 0
        arrays["rotation"] = q
    else:
        arrays[name] = eval(expr)
    np.savez(tmp_path / "field.npz", **arrays)
    path = tmp_path / "bad.yaml"
    path.write_text(HEAD + "  - name: boxes\n    mesh: box.obj\n    instances: {file: field.npz}\n")
    for command in (["check", str(path)], ["render", str(path), "-q"]):
        res = CliRunner().invoke(main, command)
        assert res.exit_code == 2 and words in res.output and "objects.0.instances" in res.output, res.output
        assert len(res.output.strip().splitlines()) == 1


def test_inline_rows_must_cover_every_instance(tmp_path):
    _box(tmp_path)
    path = tmp_path / "rows.yaml"
    path.write_text(HEAD + "  - name: boxes\n    mesh: box.obj\n    instances:\n      keys:\n"
                           "        - {t: 0, translation: [[0, 0, 0], [1, 0, 0]]}\n"
                           "        - {t: 1, translation: [[0, 0, 0], [1, 0, 0]], scale: [1, 2]}\n")
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2 and "objects.0.instances.keys.0.scale" in res.output, res.output
    path.write_text(HEAD + "  - name: boxes\n    mesh: box.obj\n    instances: {keys: [{t: 0, translation: "
                           "[[0, 0, 0]]}], file: x.npz}\n")
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2 and "exactly one of 'keys' or 'file'" in res.output, res.output


def test_gltf_gpu_instancing_places_each_copy_under_its_node(tmp_path):
    """EXT_mesh_gpu_instancing: copy i is node_world @ T_i R_i S_i (scipy's
    rotation of the x y z w quaternion as the oracle), the node moving by
    its own animation; a NaN among the copies is one line and exit 2."""
    from scipy.spatial.transform import Rotation
    from anim.scene import AnimatedScene
    from tests.gltf_files import GltfBuilder
    rng = np.random.default_rng(2)
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    n = 6
    tr, q, sc = rng.uniform(-2, 2, (n, 3)), rng.normal(size=(n, 4)), rng.uniform(0.5, 2, (n, 3))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    b = GltfBuilder()
    mesh = b.mesh(pos, np.array([0, 1, 2]))
    attrs = {"TRANSLATION": b.accessor(tr), "ROTATION": b.accessor(q), "SCALE": b.accessor(sc)}
    node = b.node(mesh=mesh, extensions={"EXT_mesh_gpu_instancing": {"attributes": attrs}})
    b.animation([(node, "translation", np.array([0.0, 1.0]), np.array([[0, 0, 0], [0, 0, 4.0]]), "LINEAR")])
    b.doc.extensionsUsed = ["EXT_mesh_gpu_instancing"]
    b.save(tmp_path / "copies.glb", [node])
    path = tmp_path / "g.yaml"
    path.write_text(HEAD + "  - name: copies\n    mesh: copies.glb\n")
    scene = AnimatedScene(path)
    assert len(scene.faces) == n
    for t in (0.0, 0.5):
        want = np.einsum("nij,nvj->nvi", Rotation.from_quat(q).as_matrix(), pos[None] * sc[:, None])
        want += tr[:, None] + [0, 0, 4 * t]
        np.testing.assert_allclose(scene.vertices_at(t).reshape(n, 3, 3), want, atol=1e-5)
    q[3, 1] = np.nan
    b2 = GltfBuilder()
    mesh = b2.mesh(pos, np.array([0, 1, 2]))
    node = b2.node(mesh=mesh, extensions={"EXT_mesh_gpu_instancing": {"attributes": {"ROTATION": b2.accessor(q)}}})
    b2.save(tmp_path / "copies.glb", [node])
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2 and "ROTATION holds inf or NaN" in res.output, res.output


@pytest.mark.parametrize("arrays, words", [
    (dict(t=np.array([0.0]), translation=np.array([[["a", "b", "c"]]])), "translation holds <U1; expected numbers"),
    (dict(t=np.array([0.0]), translation=np.zeros((1, 2, 3), complex)), "translation holds complex128"),
    (dict(t=np.array([0.0]), translation=np.zeros((1, 2, 3)), visible=np.array([[0.5, 1.0]])), "visible holds float64"),
    (dict(t=np.zeros(0), translation=np.zeros((0, 2, 3))), "t has shape (0,)"),
    (None, "cannot read field.npz as .npz"),
])
def test_an_instance_file_of_the_wrong_kind_is_one_line_and_exit_2(tmp_path, arrays, words):
    """Strings, complex numbers, fractional visibility, no keys, not an .npz."""
    _box(tmp_path)
    if arrays is None:
        (tmp_path / "field.npz").write_bytes(b"PK\x03\x04 cut short")
    else:
        np.savez(tmp_path / "field.npz", **arrays)
    path = tmp_path / "bad.yaml"
    path.write_text(HEAD + "  - name: boxes\n    mesh: box.obj\n    instances: {file: field.npz}\n")
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2 and words in res.output and "objects.0.instances.file" in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1


def test_copies_that_would_not_fit_are_refused_before_they_are_made(tmp_path, monkeypatch):
    """Instances are made into the frame's triangles: more of them than the
    free memory holds (~220 bytes a triangle) is one line and exit 2,
    naming the copies, before any is made (here: 9 copies of 12 triangles
    against 20 KB)."""
    import anim.memory
    _box(tmp_path)
    tr, q, scale = _data()
    path = _instanced(tmp_path, tr, q, scale)
    monkeypatch.setattr(anim.memory, "available_bytes", lambda: 20_000)
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2 and "9 copies of 12 triangles make 108 triangles" in res.output, res.output
    assert "objects.0.instances" in res.output and len(res.output.strip().splitlines()) == 1
    monkeypatch.setattr(anim.memory, "available_bytes", lambda: None)          # unknown: no refusal
    assert CliRunner().invoke(main, ["check", str(path)]).exit_code == 0


def _frames(path, instancing, times, **cfg):
    """(Z, RGBA, id) of frames at `times` rendered with render.instancing = instancing."""
    from anim.render.renderer import SceneRenderer
    from anim.render.settings import config_of
    from anim.scene import AnimatedScene
    from raycore.frame import Shading
    scene = AnimatedScene(path, instancing=instancing)
    assert bool(scene.two_level) == (instancing == "two_level")
    c = config_of(scene, **cfg)
    r = SceneRenderer(scene, c, Shading(scene.material_table, np.zeros(3, np.float32), np.zeros((0, 3), np.int64),
                                        scene.light_table))
    out = []
    for t in times:
        res = r.render(t)[1]
        out.append((res.z.copy(), res.rgba.copy(), res.aovs["id"].copy() if "id" in res.aovs else None))
    return out


def _field(tmp_path):
    """A ground, a bending prototype of its own motion and copies of it that
    move, one hidden from the second key on, and a box that moves in the
    world (its triangles gathered again every frame), under a point and a sun."""
    tr, q, scale = _data(7)
    visible = np.ones((K, N), bool)
    visible[1:, 3] = False
    np.savez(tmp_path / "field.npz", t=np.array(TIMES), translation=tr * [1, 0.3, 1], rotation=q, scale=scale,
             visible=visible)
    _box(tmp_path)
    (tmp_path / "ground.obj").write_text("v -9 -2 -9\nv 9 -2 -9\nv 9 -2 9\nv -9 -2 9\nf 1 3 2\nf 1 4 3\n")
    path = tmp_path / "two.yaml"
    path.write_text(HEAD.replace("[48, 48]", "[96, 80]").replace(
        "lights: [{position: [3, 6, 4], intensity: 40}]",
        "lights: [{position: [3, 6, 4], intensity: 40}, {type: directional, direction: [-0.3, -1, -0.2]}]")
        + "  - name: ground\n    mesh: ground.obj\n"
        + "  - name: boxes\n    mesh: box.obj\n" + OWN + "    instances: {file: field.npz}\n"
        + "  - name: mover\n    mesh: box.obj\n"
        + "    transform: {translation: {keys: [[0, -3, -1, 1], [1, 3, 1, 1]]}}\n")
    return path


def _agree(a, b, share=0.999):
    """Z of the same pixels within float32 rounding on >= share of them, the
    same primitive ids, colours alike but where a shadow ray grazes."""
    for (za, ca, ia), (zb, cb, ib) in zip(a, b):
        both_inf = np.isinf(za) & np.isinf(zb)
        assert np.mean(np.isclose(za, zb, rtol=1e-4) | both_inf) >= share
        assert np.isfinite(za).mean() > 0.2
        if ia is not None:
            assert np.mean(ia == ib) >= share
        assert np.mean(np.abs(ca - cb).max(axis=2) < 1e-3) >= share


def test_two_level_frames_are_the_flattened_frames(tmp_path):
    """render.instancing two_level (a tree for the prototype, a top level
    over the copies) against flatten (every copy's triangles) on the same
    scene: the same depth, ids (the flattened world's numbering, so objects
    after the copies keep theirs) and colours, while the copies and the
    prototype move and one copy hides."""
    path = _field(tmp_path)
    times = [0.0, 0.4, 0.95]
    flat = _frames(path, "flatten", times, aovs=("id",), accel="bvh")
    two = _frames(path, "two_level", times, aovs=("id",))
    _agree(flat, two)
    assert len(np.unique(two[1][2])) > 10


def test_two_level_under_motion_blur_and_an_error_budget(tmp_path):
    """Each pass of a motion-blurred frame places the copies at its own
    time, as the flattened frame moves their triangles; the error budget's
    ray batches carry the instances too."""
    path = _field(tmp_path)
    kw = dict(spp=4, shutter=0.5, accel="bvh")
    _agree(_frames(path, "flatten", [0.4], **kw), _frames(path, "two_level", [0.4], **kw), share=0.995)
    kw = dict(max_error=0.02, accel="bvh")
    _agree(_frames(path, "flatten", [0.4], **kw), _frames(path, "two_level", [0.4], **kw), share=0.995)


def test_auto_instancing_copies_small_tables_and_traces_large_ones_two_level(tmp_path, monkeypatch):
    """auto: two-level from 3M copied triangles, or from 1M when the
    prototypes are large (as measured); the rule, then a scene under it."""
    import anim.instances as instances
    from anim.instances import two_level
    from anim.scene import AnimatedScene
    assert not two_level("auto", 2_999_999, 30_000) and two_level("auto", 3_000_000, 30_000)
    assert not two_level("auto", 999_999, 100) and two_level("auto", 1_000_000, 100)
    assert not two_level("auto", 1_500_000, 10_000)                # 150-triangle copies
    assert two_level("two_level", 1, 1) and not two_level("flatten", 10 ** 9, 10)
    path = _field(tmp_path)
    assert not AnimatedScene(path).two_level                  # 9 copies of 12 triangles: copied
    monkeypatch.setattr(instances, "TWO_LEVEL_TRIANGLES", N * 12)
    scene = AnimatedScene(path)
    assert [o.name for o in scene.two_level] == ["boxes"]
    assert scene.faces.shape[0] == 2 + 12 + 12 and scene.flat_triangles == 2 + N * 12 + 12


def test_gltf_gpu_instancing_two_level_places_the_copies_the_flattened_frame_has(tmp_path):
    """EXT_mesh_gpu_instancing traced two-level: the primitive once, each
    copy's matrix node_world @ T_i R_i S_i (scipy's rotations as the
    oracle) while the node moves, and the frames those of the copies made
    into triangles."""
    from scipy.spatial.transform import Rotation
    from anim.scene import AnimatedScene
    from conftest import icosphere_mesh
    from tests.gltf_files import GltfBuilder
    rng = np.random.default_rng(4)
    v, f = icosphere_mesh(2, 0.4)
    n = 40
    tr, q, sc = rng.uniform(-3, 3, (n, 3)) * [1, 0.6, 0.5], rng.normal(size=(n, 4)), rng.uniform(0.5, 1.5, (n, 3))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    b = GltfBuilder()
    mesh = b.mesh(np.asarray(v, np.float32), np.asarray(f, np.uint32).reshape(-1))
    attrs = {"TRANSLATION": b.accessor(tr), "ROTATION": b.accessor(q), "SCALE": b.accessor(sc)}
    node = b.node(mesh=mesh, extensions={"EXT_mesh_gpu_instancing": {"attributes": attrs}})
    b.animation([(node, "translation", np.array([0.0, 1.0]), np.array([[0, 0, 0], [0, 0, 2.0]]), "LINEAR")])
    b.doc.extensionsUsed = ["EXT_mesh_gpu_instancing"]
    b.save(tmp_path / "copies.glb", [node])
    (tmp_path / "ground.obj").write_text("v -9 -2 -9\nv 9 -2 -9\nv 9 -2 9\nv -9 -2 9\nf 1 3 2\nf 1 4 3\n")
    path = tmp_path / "g.yaml"
    path.write_text(HEAD.replace("[48, 48]", "[96, 80]") + "  - name: ground\n    mesh: ground.obj\n"
                    "  - name: copies\n    mesh: copies.glb\n")
    scene = AnimatedScene(path, instancing="two_level")
    assert len(scene.faces) == 2 + len(f) and scene.flat_triangles == 2 + n * len(f)
    for t in (0.0, 0.5):
        m = scene.instances_at(t).matrices
        np.testing.assert_allclose(m[:, :, :3], Rotation.from_quat(q).as_matrix() * sc[:, None, :], atol=1e-6)
        np.testing.assert_allclose(m[:, :, 3], tr + [0, 0, 2 * t], atol=1e-6)
    times = [0.0, 0.5]
    _agree(_frames(path, "flatten", times, aovs=("id",), accel="bvh"), _frames(path, "two_level", times, aovs=("id",)))


def test_gltf_nodes_sharing_a_mesh_two_level_are_the_flattened_frames(tmp_path):
    """Nodes that show one mesh, traced two-level: the mesh once, a copy
    per node placed by the node's world transform (one node animated,
    others under a parent, a single-use mesh between them), against the
    copies made into triangles: depth, ids (each node's place in the
    flattened numbering) and colours."""
    from anim.scene import AnimatedScene
    from conftest import icosphere_mesh
    from tests.gltf_files import GltfBuilder
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(8)
    v, f = icosphere_mesh(2, 0.5)
    b = GltfBuilder()
    ball = b.mesh(np.asarray(v, np.float32), np.asarray(f, np.uint32).reshape(-1))
    tri = b.mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), np.array([0, 1, 2], np.uint32))
    nodes = []
    for k in range(12):
        q = Rotation.random(random_state=k).as_quat()
        nodes.append(b.node(mesh=ball, translation=list(rng.uniform(-3, 3, 3) * [1, 0.6, 0.3]),
                            rotation=list(q), scale=list(rng.uniform(0.5, 1.2, 3))))
        if k == 5:
            nodes.append(b.node(mesh=tri, translation=[0.0, -1.0, 0.5]))
    parent = b.node(children=nodes[6:], translation=[0.5, 0.2, 0.0])
    b.animation([(nodes[1], "translation", np.array([0.0, 1.0]), np.array([[0, 0, 0], [0, 1.5, 0.0]]), "LINEAR")])
    b.save(tmp_path / "balls.glb", nodes[:6] + [parent])
    (tmp_path / "ground.obj").write_text("v -9 -2 -9\nv 9 -2 -9\nv 9 -2 9\nv -9 -2 9\nf 1 3 2\nf 1 4 3\n")
    path = tmp_path / "g.yaml"
    path.write_text(HEAD.replace("[48, 48]", "[96, 80]") + "  - name: balls\n    mesh: balls.glb\n"
                    "  - name: ground\n    mesh: ground.obj\n")
    scene = AnimatedScene(path, instancing="two_level")
    assert len(scene.instance_proto) == 12 and len(scene.proto_ranges) == 1
    assert len(scene.faces) == len(f) + 1 + 2 and scene.flat_triangles == 12 * len(f) + 1 + 2
    times = [0.0, 0.5]
    _agree(_frames(path, "flatten", times, aovs=("id",), accel="bvh"), _frames(path, "two_level", times, aovs=("id",)))


@pytest.mark.parametrize("far", [0.0, 1.0e5])
def test_two_level_textured_copies_and_aovs_far_from_the_origin(tmp_path, far):
    """Textured copies (the demo's checkered floor tile), traced two-level
    and flattened, near the origin and a hundred thousand units from it:
    the same hits, colours (UVs carried by the seen triangles), N and P;
    the two-level depth against the copies' planes in float64 as exact
    there as at the origin (rays enter a copy's space by L^-1 (p - T), the
    subtraction in float64), where the flattened copies' float32 corners
    put depth ~1e-4 out."""
    import shutil
    from importlib.resources import files
    from scipy.spatial.transform import Rotation
    from anim.render.renderer import SceneRenderer
    from anim.render.settings import config_of, shading_of
    from anim.scene import AnimatedScene
    from raycore.geometry.camera import camera_basis, primary_dir
    demo = files("anim.builtin") / "demo"
    for name in ("floor.obj", "checker.png"):
        shutil.copy(demo / name, tmp_path / name)
    rng = np.random.default_rng(11)
    n = 12
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    tr = np.c_[rng.uniform(-3, 3, n), rng.uniform(-1.5, 1.5, n), rng.uniform(-2, 0, n)] + [far, 0, 0]
    np.savez(tmp_path / "tiles.npz", t=np.array([0.0]), translation=tr[None], rotation=q[None],
             scale=np.full((1, n), 0.25))
    path = tmp_path / "tiles.yaml"
    path.write_text(f"""version: 1
frames: {{start: 0, end: 0, fps: 24}}
output: {{path: out/f_##.exr, resolution: [96, 80], aovs: [N, P, id]}}
camera: {{eye: [{far}, 2, 9], look_at: [{far}, 0, 0], fov: 50}}
lights: [{{position: [{far + 3}, 6, 4], intensity: 40}}]
materials: {{checks: {{diffuse: [1, 1, 1], texture: checker.png}}}}
objects:
  - name: tiles
    mesh: floor.obj
    material: checks
    instances: {{file: tiles.npz}}
""")
    got = {}
    for instancing in ("flatten", "two_level"):
        scene = AnimatedScene(path, instancing=instancing)
        got[instancing] = SceneRenderer(scene, config_of(scene, accel="bvh"), shading_of(scene)).render(0.0)[1]
    a, b = got["flatten"], got["two_level"]
    assert np.isfinite(b.z).mean() > 0.1
    assert np.mean(a.aovs["id"] == b.aovs["id"]) >= 0.995
    # 10^5 units out the flattened copies' float32 corners move the checks' edges (the two-level
    # barycentrics, and so the UVs, come from the copy's own space): a few more pixels differ there
    assert np.mean(np.abs(a.rgba - b.rgba).max(axis=2) < 2e-3) >= (0.99 if far == 0 else 0.97)
    assert len(np.unique(np.round(b.rgba[..., 0][np.isfinite(b.z)], 2))) > 4        # checks, not one colour
    for name in ("N.X", "N.Y", "N.Z"):          # the flattened normals, from rounded corners, as far off
        assert np.mean(np.abs(a.aovs[name] - b.aovs[name]) < (1e-3 if far == 0 else 1e-2)) >= 0.99
    for name in ("P.X", "P.Y", "P.Z"):
        assert np.mean(np.isclose(a.aovs[name], b.aovs[name], rtol=1e-6, atol=0.05)) >= 0.99
    # two-level depth against each hit copy's triangle plane in float64
    eye, look = np.array([far, 2.0, 9.0]), np.array([far, 0.0, 0.0])
    forward = (look - eye) / np.linalg.norm(look - eye)
    cam = camera_basis(tuple(eye), tuple(look), (0, 1, 0), 50.0, 96, 80)
    rot = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    tile = np.array([[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], np.float64) * 0.25
    corners = [[0, 2, 1], [0, 3, 2]]                       # floor.obj's two triangles
    err = []
    for y, x in zip(*np.nonzero(np.isfinite(b.z))):
        copy, t = divmod(int(b.aovs["id"][y, x]), 2)
        p = tile[corners[t]] @ rot[copy].T + tr[copy]
        normal = np.cross(p[1] - p[0], p[2] - p[0])
        d = np.array(primary_dir(cam, x, y, np.float32(0.5), np.float32(0.5)), np.float64)
        z = np.dot(p[0] - eye, normal) / np.dot(d, normal) * np.dot(d, forward)
        err.append(abs(b.z[y, x] - z) / z)
    assert np.percentile(err, 99) < 1e-5, np.percentile(err, 99)
