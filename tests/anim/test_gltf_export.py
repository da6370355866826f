"""glTF as exporters write it (issue 22): sparse accessors for every kind of
accessor, several animations played together (`animation: all` or a list),
and the file's own materials per primitive. Motion is checked against an
independent numpy/scipy evaluation, and the rendered depth against the
same scene made of that evaluated mesh."""
import numpy as np
import pygltflib as gl
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from anim.render.settings import shading_of
from anim.scene import AnimatedScene
from cli.main import main
from gltf_files import GltfBuilder

QUAD = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
QUAD_FACES = [0, 1, 2, 0, 2, 3]


def _scene(tmp_path, mesh, extra="", res=32, frames=2, light="{type: directional, direction: [0, 0, -1], intensity: 1}"):
    path = tmp_path / "s.yaml"
    path.write_text(f"""version: 1
frames: {{start: 0, end: {frames}, fps: 2}}
output: {{path: out/f_#.exr, resolution: [{res}, {res}]}}
camera: {{eye: [0, 0, 6], look_at: [0, 0, 0], fov: 45}}
lights: [{light}]
objects:
  - name: thing
    mesh: {mesh}
{extra}""")
    return path


def _tube(n_around=12, n_along=6):
    """A small open cylinder along x: (vertices, faces)."""
    a = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    x = np.linspace(-1.5, 1.5, n_along)
    verts = np.array([[xi, 0.5 * np.cos(ai), 0.5 * np.sin(ai)] for xi in x for ai in a], np.float32)
    faces = []
    for i in range(n_along - 1):
        for j in range(n_around):
            p, q = i * n_around + j, i * n_around + (j + 1) % n_around
            faces += [p, q, q + n_around, p, q + n_around, p + n_around]
    return verts, np.array(faces)


def _bulge(verts):
    """A morph target moving the middle ring outwards (few vertices: sparse)."""
    rows = np.nonzero(np.abs(verts[:, 0]) < 0.4)[0]
    delta = verts[rows].copy()
    delta[:, 0] = 0
    return rows, 0.6 * delta


def _character(path):
    """A tube with a bulging shape key (sparse morph target, no buffer view)
    and two animations as Blender writes one per action: 'rigAction' turns
    the node about z, 'CylinderAction' drives the shape key's weight."""
    b = GltfBuilder()
    verts, faces = _tube()
    rows, delta = _bulge(verts)
    target = b.sparse_accessor(None, len(verts), rows, delta)
    prim = gl.Primitive(attributes=gl.Attributes(POSITION=b.accessor(verts)),
                        indices=b.accessor(faces.reshape(-1, 1), 5125), targets=[{"POSITION": target}])
    b.doc.meshes.append(gl.Mesh(primitives=[prim], weights=[0.0]))
    node = b.node(mesh=0, name="Cylinder")
    b.animation([(node, "rotation", [0.0, 1.0], np.stack([_zquat(0), _zquat(60)]), "LINEAR")], name="rigAction")
    b.animation([(node, "weights", [0.0, 1.0], np.array([[0.0], [1.0]]), "LINEAR")], name="CylinderAction")
    b.save(path, [node])
    return verts, faces, rows, delta


def _zquat(deg):
    return Rotation.from_euler("z", deg, degrees=True).as_quat()


def _evaluate(verts, rows, delta, t, rotate=True, bulge=True):
    """The character at time t, evaluated independently of frustrace."""
    s = min(max(t, 0.0), 1.0)
    v = verts.astype(np.float64).copy()
    if bulge:
        v[rows] += s * delta
    if rotate:
        v = Rotation.from_euler("z", 60 * s, degrees=True).apply(v)
    return v


@pytest.mark.parametrize("name", ["sparse.glb", "sparse.gltf"])
def test_sparse_accessors_of_every_kind(tmp_path, name):
    """Positions (a buffer view with rows replaced), a morph target (zeros
    plus rows), key times and weight values of an animation, all sparse."""
    b = GltfBuilder()
    moved = QUAD.copy()
    moved[2] = [1.5, 1.5, 0.25]
    positions = b.sparse_accessor(QUAD, 4, [2], moved[2:3])
    target = b.sparse_accessor(None, 4, [0, 3], [[0, 0, 1], [0, 0, -1]], index_component=5121)
    prim = gl.Primitive(attributes=gl.Attributes(POSITION=positions),
                        indices=b.accessor(np.array(QUAD_FACES).reshape(-1, 1), 5125),
                        targets=[{"POSITION": target}])
    b.doc.meshes.append(gl.Mesh(primitives=[prim], weights=[0.0]))
    node = b.node(mesh=0)
    times = b.sparse_accessor([0.0, 0.5, 9.0], 3, [2], [[2.0]])              # key times 0, 0.5, 2
    weights = b.sparse_accessor(None, 3, [1, 2], [[1.0], [0.5]])           # weights 0, 1, 0.5
    b.doc.animations.append(gl.Animation(
        name="w", samplers=[gl.AnimationSampler(input=times, output=weights, interpolation="LINEAR")],
        channels=[gl.AnimationChannel(sampler=0, target=gl.AnimationChannelTarget(node=node, path="weights"))]))
    b.save(tmp_path / name, [node])
    scene = AnimatedScene(_scene(tmp_path, name))
    dz = np.array([[0, 0, 1], [0, 0, 0], [0, 0, 0], [0, 0, -1]], np.float64)
    for t, w in ((0.0, 0.0), (0.25, 0.5), (0.5, 1.0), (1.25, 0.75), (2.0, 0.5), (3.0, 0.5)):
        np.testing.assert_allclose(scene.vertices_at(t), moved + w * dz, atol=1e-6)


def _sparse_file(tmp_path, positions, count=4):
    b = GltfBuilder()
    acc = b.sparse_accessor(QUAD, count, positions, np.zeros((len(positions), 3)))
    prim = gl.Primitive(attributes=gl.Attributes(POSITION=acc),
                        indices=b.accessor(np.array(QUAD_FACES).reshape(-1, 1), 5125))
    b.doc.meshes.append(gl.Mesh(primitives=[prim]))
    b.save(tmp_path / "bad.glb", [b.node(mesh=0)])
    return _scene(tmp_path, "bad.glb")


@pytest.mark.parametrize("positions, problem", [([2, 1], "must increase"), ([1, 9], "below its count")])
def test_bad_sparse_indices_are_one_line_errors(tmp_path, positions, problem):
    res = CliRunner().invoke(main, ["check", str(_sparse_file(tmp_path, positions))])
    assert res.exit_code == 2, res.output
    assert "objects.0.mesh" in res.output and "bad.glb" in res.output and problem in res.output
    assert len(res.output.strip().splitlines()) == 1


def test_blender_style_actions_play_together_with_animation_all(tmp_path):
    verts, _, rows, delta = _character(tmp_path / "char.glb")
    # the default plays the first animation only, and check says what is left out
    res = CliRunner().invoke(main, ["check", str(_scene(tmp_path, "char.glb"))])
    assert res.exit_code == 0, res.output
    assert "'CylinderAction'" in res.output and "animation: all" in res.output and "objects.0.animation" in res.output
    scene = AnimatedScene(_scene(tmp_path, "char.glb"))
    np.testing.assert_allclose(scene.vertices_at(0.7), _evaluate(verts, rows, delta, 0.7, bulge=False), atol=1e-5)
    for extra, rotate, bulge in (("    animation: all\n", True, True),
                                 ("    animation: [CylinderAction]\n", False, True),
                                 ("    animation: [1, rigAction]\n", True, True)):
        scene = AnimatedScene(_scene(tmp_path, "char.glb", extra))
        assert not any("is not played" in w for w in scene.warnings) or not (rotate and bulge)
        for t in (0.0, 0.35, 0.7, 1.0, 1.5):
            np.testing.assert_allclose(scene.vertices_at(t), _evaluate(verts, rows, delta, t, rotate, bulge),
                                       atol=1e-5)


@pytest.mark.parametrize("extra, words", [
    ("    animation: [0, rigAction]\n", ["chosen twice"]),
    ("    animation: [rigAction, walk]\n", ["walk", "rigAction", "CylinderAction"]),
    ("    animation: []\n", ["objects.0.animation"]),
])
def test_bad_animation_choices(tmp_path, extra, words):
    _character(tmp_path / "char.glb")
    res = CliRunner().invoke(main, ["check", str(_scene(tmp_path, "char.glb", extra))])
    assert res.exit_code == 2, res.output
    assert all(w in res.output for w in words), res.output


def test_two_played_animations_on_one_property_are_an_error_naming_both(tmp_path):
    b = GltfBuilder()
    node = b.node(mesh=b.mesh(QUAD, QUAD_FACES), name="Arm")
    b.animation([(node, "rotation", [0.0, 1.0], np.stack([_zquat(0), _zquat(30)]), "LINEAR")], name="wave")
    b.animation([(node, "rotation", [0.0, 1.0], np.stack([_zquat(0), _zquat(-30)]), "LINEAR")], name="point")
    b.save(tmp_path / "arm.glb", [node])
    res = CliRunner().invoke(main, ["check", str(_scene(tmp_path, "arm.glb", "    animation: all\n"))])
    assert res.exit_code == 2
    assert "'wave'" in res.output and "'point'" in res.output and "rotation" in res.output
    still = GltfBuilder()
    still.save(tmp_path / "still.glb", [still.node(mesh=still.mesh(QUAD, QUAD_FACES))])
    assert AnimatedScene(_scene(tmp_path, "still.glb", "    animation: all\n")).objects[0].static


def test_rendered_depth_equals_the_independently_evaluated_mesh(tmp_path):
    """`animation: all` on the Blender-style file against a scene of the
    numpy-evaluated mesh, frame by frame: the same depth on every pixel."""
    verts, faces, rows, delta = _character(tmp_path / "char.glb")
    fps = 4
    out_a, out_b = tmp_path / "a", tmp_path / "b"
    path = _scene(tmp_path, "char.glb", "    animation: all\n", res=48, frames=5)
    text = path.read_text().replace("fps: 2", f"fps: {fps}")
    path.write_text(text.replace("out/f_#.exr", f"{out_a}/f_#.exr"))
    objs = []
    for f in range(6):
        v = _evaluate(verts, rows, delta, f / fps).astype(np.float32)
        obj = tmp_path / f"char_{f}.obj"
        obj.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in v.tolist())
                       + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces.reshape(-1, 3)))
        objs.append(f"      - {{t: {f / fps!r}, mesh: {obj.name}}}\n")
    ref = tmp_path / "ref.yaml"
    ref.write_text(text.replace("out/f_#.exr", f"{out_b}/f_#.exr")
                   .replace("    mesh: char.glb\n    animation: all\n", "    interpolation: linear\n    keyframes:\n"
                            + "".join(objs)))
    for scene_path in (path, ref):
        res = CliRunner().invoke(main, ["render", str(scene_path), "--quiet", "--no-shadows"])
        assert res.exit_code == 0, res.output
    from raycore.images.image_io import read_exr
    for f in range(6):
        za = read_exr(str(out_a / f"f_{f}.exr"))
        zb = read_exr(str(out_b / f"f_{f}.exr"))
        a, b = za[1][..., za[0].index("Z")], zb[1][..., zb[0].index("Z")]
        assert np.isfinite(a).sum() > 100
        np.testing.assert_allclose(a, b, rtol=1e-5)


def _two_quads(b, mat_left, mat_right):
    prims = []
    for dx, mat in ((-1.1, mat_left), (1.1, mat_right)):
        verts = QUAD + [dx, 0, 0]
        prims.append(gl.Primitive(attributes=gl.Attributes(POSITION=b.accessor(verts)), material=mat,
                                  indices=b.accessor(np.array(QUAD_FACES).reshape(-1, 1), 5125)))
    b.doc.meshes.append(gl.Mesh(primitives=prims))
    return b.node(mesh=len(b.doc.meshes) - 1)


def test_each_primitive_gets_its_own_material_unless_the_scene_names_one(tmp_path):
    b = GltfBuilder()
    red = b.material([0.9, 0.1, 0.1], roughness=0.5, name="red")
    blue = b.material([0.1, 0.1, 0.9], metallic=1.0, roughness=0.2)
    node = _two_quads(b, red, blue)
    b.save(tmp_path / "two.glb", [node])
    scene = AnimatedScene(_scene(tmp_path, "two.glb"))
    table = scene.material_table
    left, right = table[scene.tri_material[0]], table[scene.tri_material[-1]]
    np.testing.assert_allclose(left[:3], [0.9, 0.1, 0.1], rtol=1e-6)
    np.testing.assert_allclose(right[:3], [0.1, 0.1, 0.9], rtol=1e-6)
    np.testing.assert_allclose([left[3], right[3]], [0.04, 1.0], rtol=1e-6)          # specular weight
    np.testing.assert_allclose([left[4], right[4]], [2 / 0.5 ** 4 - 2, 2 / 0.2 ** 4 - 2], rtol=1e-5)
    res = CliRunner().invoke(main, ["render", str(_scene(tmp_path, "two.glb")), "--quiet", "--no-shadows"])
    assert res.exit_code == 0, res.output
    from raycore.images.image_io import read_exr
    names, pix, _ = read_exr(str(tmp_path / "out" / "f_0.exr"))
    r, g, bl = (pix[16, :, names.index(c)] for c in "RGB")
    assert r[8] > 4 * bl[8] and bl[24] > 4 * r[24]            # left red, right blue
    # the scene's material overrides the file's
    override = _scene(tmp_path, "two.glb", "    material: grey\n").read_text()
    override = override.replace("objects:", "materials: {grey: {diffuse: [0.5, 0.5, 0.5]}}\nobjects:")
    (tmp_path / "o.yaml").write_text(override)
    scene = AnimatedScene(tmp_path / "o.yaml")
    assert set(scene.material_table[scene.tri_material][:, 0]) == {np.float32(0.5)}


def _png(tmp_path, rgb):
    from raycore.images.image_io import _write_8bit
    path = tmp_path / "tex.png"
    _write_8bit(str(path), np.asarray(rgb, np.uint8))
    return path.read_bytes()


def test_base_colour_texture_with_its_texcoord_set_and_khr_texture_transform(tmp_path):
    b = GltfBuilder()
    png = _png(tmp_path, [[[255, 0, 0], [0, 255, 0]]])                    # 2 x 1: red | green
    transform = {"offset": [0.25, -0.5], "rotation": 0.3, "scale": [2.0, 0.5], "texCoord": 1}
    mat = b.material([1.0, 1.0, 1.0], texture=(png, 0, transform))
    uv0 = np.zeros((4, 2), np.float32)
    uv1 = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    prim = gl.Primitive(attributes=gl.Attributes(POSITION=b.accessor(QUAD), TEXCOORD_0=b.accessor(uv0),
                                                 TEXCOORD_1=b.accessor(uv1)),
                        indices=b.accessor(np.array(QUAD_FACES).reshape(-1, 1), 5125), material=mat)
    b.doc.meshes.append(gl.Mesh(primitives=[prim]))
    b.save(tmp_path / "tex.glb", [b.node(mesh=0)])
    scene = AnimatedScene(_scene(tmp_path, "tex.glb"))
    c, s = np.cos(0.3), np.sin(0.3)
    u, v = uv1[:, 0] * 2.0, uv1[:, 1] * 0.5
    want = np.stack([0.25 + c * u + s * v, 1 - (-0.5 - s * u + c * v)], axis=1)    # v flipped
    np.testing.assert_allclose(scene.uvs, want, atol=1e-6)
    shading = shading_of(scene)
    assert shading.tex_info.tolist() == [[0, 2, 1]]
    np.testing.assert_allclose(shading.tex_data[:6], [1, 0, 0, 0, 1, 0], atol=1e-6)   # sRGB 255 -> 1


def test_a_texture_whose_image_is_only_in_an_extension_is_a_warning(tmp_path):
    """KHR_texture_basisu and EXT_texture_webp may leave `source` out: the
    material's colour factor is used, as by a viewer without the extension."""
    b = GltfBuilder()
    mat = b.material([0.2, 0.4, 0.6], texture=(_png(tmp_path, [[[255, 0, 0]]]), 0, None))
    b.doc.textures[0] = gl.Texture(source=None, extensions={"KHR_texture_basisu": {"source": 0}})
    prim = gl.Primitive(attributes=gl.Attributes(POSITION=b.accessor(QUAD)),
                        indices=b.accessor(np.array(QUAD_FACES).reshape(-1, 1), 5125), material=mat)
    b.doc.meshes.append(gl.Mesh(primitives=[prim]))
    b.save(tmp_path / "ktx.glb", [b.node(mesh=0)])
    scene = AnimatedScene(_scene(tmp_path, "ktx.glb"))
    assert any("extension" in w for w in scene.warnings)
    row = scene.material_table[scene.tri_material[0]]
    np.testing.assert_allclose(row[:3], [0.2, 0.4, 0.6], rtol=1e-6)
    assert row[5] == -1 and scene.texture_paths == []


def test_compressed_geometry_is_refused_in_one_line(tmp_path):
    b = GltfBuilder()
    b.doc.extensionsUsed = b.doc.extensionsRequired = ["KHR_draco_mesh_compression"]
    b.save(tmp_path / "draco.glb", [b.node(mesh=b.mesh(QUAD, QUAD_FACES))])
    res = CliRunner().invoke(main, ["check", str(_scene(tmp_path, "draco.glb"))])
    assert res.exit_code == 2 and "KHR_draco_mesh_compression" in res.output and "objects.0.mesh" in res.output


def test_the_older_specular_glossiness_materials(tmp_path):
    b = GltfBuilder()
    mat = b.material([1.0, 1.0, 1.0])
    b.doc.materials[mat].pbrMetallicRoughness = None
    b.doc.materials[mat].extensions = {"KHR_materials_pbrSpecularGlossiness": {
        "diffuseFactor": [0.3, 0.5, 0.7, 1.0], "specularFactor": [0.04, 0.04, 0.04], "glossinessFactor": 0.6}}
    prim = gl.Primitive(attributes=gl.Attributes(POSITION=b.accessor(QUAD)),
                        indices=b.accessor(np.array(QUAD_FACES).reshape(-1, 1), 5125), material=mat)
    b.doc.meshes.append(gl.Mesh(primitives=[prim]))
    b.save(tmp_path / "sg.glb", [b.node(mesh=0)])
    scene = AnimatedScene(_scene(tmp_path, "sg.glb"))
    row = scene.material_table[scene.tri_material[0]]
    np.testing.assert_allclose(row[:5], [0.3, 0.5, 0.7, 0.04, 2 / 0.4 ** 4 - 2], rtol=1e-5)
