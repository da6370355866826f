"""USD instancing (anim/io/usd_instancer.py, usd.mesh_prims): a
PointInstancer and instanceable prims render with the depth of the same
world written without instancing (each copy an Xform with translate,
orient and scale ops time-sampled as the instancer's positions,
orientations and scales, over a reference to the prototype: usd-core's
XformCache composes those, not the PointInstancer code), while instances
move, turn, scale, and the instancer itself moves; invisibleIds hide a
copy. Bad instancers are one line and exit 2."""
import numpy as np
import pytest
from click.testing import CliRunner

from cli.main import main
from raycore.images.image_io import read_exr

pytest.importorskip("pxr")
from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, Vt  # noqa: E402

from tests.usd_files import mesh, new_stage, tube  # noqa: E402

N = 14
HIDDEN = 3


def _camera(stage):
    cam = UsdGeom.Camera.Define(stage, "/Cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(0, 0, 13))
    cam.GetFocalLengthAttr().Set(18.0)


def _prototypes(stage, root):
    """Two prototypes under root: a tube with its own transform, and an
    Xform holding a turned, shifted tube (a mesh below its prototype root)."""
    pts, counts, idx = tube(n_around=8, n_along=3, length=2.4, radius=0.6)
    a = mesh(stage, f"{root}/Tube", pts, counts, idx)
    UsdGeom.Xformable(a).AddTranslateOp().Set(Gf.Vec3d(-0.8, 0, 0.2))
    pair = UsdGeom.Xform.Define(stage, f"{root}/Pair")
    pair.AddScaleOp().Set(Gf.Vec3f(0.7, 0.7, 0.7))
    b = mesh(stage, f"{root}/Pair/M", pts * np.float32([1.0, 2.0, 2.0]), counts, idx)
    xf = UsdGeom.Xformable(b)
    xf.AddTranslateOp().Set(Gf.Vec3d(0, 0.5, 0))
    xf.AddRotateZOp().Set(50.0)
    return [f"{root}/Tube", f"{root}/Pair"]


def _instance_data(seed=3):
    rng = np.random.default_rng(seed)
    proto = rng.integers(0, 2, N)
    pos = {t: rng.uniform(-6, 6, (N, 3)) * [1, 1, 0.2] for t in (0, 10)}
    q = {t: rng.normal(size=(N, 4)) for t in (0, 10)}
    q = {t: v / np.linalg.norm(v, axis=1, keepdims=True) for t, v in q.items()}
    scale = {t: rng.uniform(0.6, 1.4, (N, 3)) for t in (0, 10)}
    return proto, pos, q, scale


def _instancer_ops(xf):
    xf.AddTranslateOp().Set(Gf.Vec3d(0.5, -0.3, 0), 0)
    op = xf.AddRotateZOp()
    op.Set(0.0, 0)
    op.Set(30.0, 10)


def _instanced_stage(path, data):
    proto, pos, q, scale = data
    stage = new_stage(path)
    _camera(stage)
    pi = UsdGeom.PointInstancer.Define(stage, "/World/PI")
    _instancer_ops(pi)
    pi.GetPrototypesRel().SetTargets([Sdf.Path(p) for p in _prototypes(stage, "/World/PI/Protos")])
    pi.GetProtoIndicesAttr().Set(Vt.IntArray(proto.tolist()))
    for t in (0, 10):
        pi.GetPositionsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*p) for p in pos[t]]), t)
        # float quaternions (half ones are not unit length to 1e-3, which usd-core's two paths treat apart)
        pi.GetOrientationsfAttr().Set(Vt.QuatfArray([Gf.Quatf(*v) for v in q[t]]), t)
        pi.GetScalesAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*s) for s in scale[t]]), t)
    pi.GetInvisibleIdsAttr().Set(Vt.Int64Array([HIDDEN]))
    stage.GetRootLayer().Save()


def _flat_stage(path, data):
    """The same world without instancing: an Xform per visible copy."""
    proto, pos, q, scale = data
    stage = new_stage(path)
    _camera(stage)
    protos = _prototypes(stage, "/Protos")
    stage.GetPrimAtPath("/Protos").SetSpecifier(Sdf.SpecifierClass)       # not rendered in its own right
    world = UsdGeom.Xform.Define(stage, "/World")
    _instancer_ops(world)
    for i in range(N):
        if i == HIDDEN:
            continue
        copy = UsdGeom.Xform.Define(stage, f"/World/I{i}")
        tr, orient, sc = copy.AddTranslateOp(), copy.AddOrientOp(UsdGeom.XformOp.PrecisionFloat), copy.AddScaleOp()
        for t in (0, 10):
            tr.Set(Gf.Vec3d(*pos[t][i]), t)
            orient.Set(Gf.Quatf(*q[t][i]), t)
            sc.Set(Gf.Vec3f(*scale[t][i]), t)
        name = protos[proto[i]].rsplit("/", 1)[1]
        stage.DefinePrim(f"/World/I{i}/{name}").GetReferences().AddInternalReference(protos[proto[i]])
    stage.GetRootLayer().Save()


def _depth(path, out, frames="0:10", instancing="auto"):
    res = CliRunner().invoke(main, ["render", str(path), "-o", str(out), "-q", "--no-shadows", "--res", "96x96",
                                    "--frames", frames, "--instancing", instancing])
    assert res.exit_code == 0, res.output
    depth = []
    for f in sorted(out.glob("*.exr")):
        names, pix, _ = read_exr(str(f))
        depth.append(pix[..., names.index("Z")])
    return np.array(depth)


def _same(a, b, hits=0.05):
    both = np.isfinite(a) & np.isfinite(b)
    same = (np.isinf(a) & np.isinf(b)) | (both & (np.abs(np.where(both, a, 0) - np.where(both, b, 0)) <= 1e-4 * np.abs(np.where(both, b, 1))))
    assert np.isfinite(b).mean() > hits
    assert same.mean() >= 0.999, same.mean()


@pytest.mark.parametrize("instancing", ["flatten", "two_level"])
def test_a_point_instancer_has_the_depth_of_its_flattened_world(tmp_path, instancing):
    """Copied into the frame's triangles, or traced two-level (the
    prototypes' trees, a top level over the copies, usd-core's instance
    transforms), against the same world written without instancing."""
    data = _instance_data()
    _instanced_stage(tmp_path / "pi.usda", data)
    _flat_stage(tmp_path / "flat.usda", data)
    got = _depth(tmp_path / "pi.usda", tmp_path / "a", instancing=instancing)
    want = _depth(tmp_path / "flat.usda", tmp_path / "b")
    assert len(got) == 11
    _same(got, want)
    assert not np.array_equal(np.isfinite(got[0]), np.isfinite(got[10]))       # they move


def test_a_hidden_instance_is_not_rendered_and_the_copies_are_counted(tmp_path):
    from anim.scene import AnimatedScene
    data = _instance_data()
    _instanced_stage(tmp_path / "pi.usda", data)
    scene = AnimatedScene(tmp_path / "pi.usda")
    (obj,) = [o for o in scene.objects if o.name == "/World/PI"]
    tube_tris = 2 * 8 * 2
    assert len(obj.faces) == N * tube_tris
    # unhiding the copy changes the picture
    stage = Usd.Stage.Open(str(tmp_path / "pi.usda"))
    UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/PI")).GetInvisibleIdsAttr().Set(Vt.Int64Array([]))
    stage.Save()
    flat = tmp_path / "flat.usda"
    _flat_stage(flat, data)
    shown, hidden = _depth(tmp_path / "pi.usda", tmp_path / "a", "0:0"), _depth(flat, tmp_path / "b", "0:0")
    assert np.mean(np.isfinite(shown) != np.isfinite(hidden)) > 0.001


def test_instanceable_prims_render_as_their_copies(tmp_path):
    """Two instanceable references to one prototype (instance proxies)
    render as the same references made without instancing."""
    out = []
    for instanceable in (True, False):
        path = tmp_path / f"i{instanceable}.usda"
        stage = new_stage(path)
        _camera(stage)
        _prototypes(stage, "/Proto")
        stage.GetPrimAtPath("/Proto").SetSpecifier(Sdf.SpecifierClass)
        for k, x in enumerate((-3.0, 2.5)):
            copy = UsdGeom.Xform.Define(stage, f"/World/C{k}")
            copy.AddTranslateOp().Set(Gf.Vec3d(x, 1.0 * k, 0))
            copy.AddRotateZOp().Set(40.0 * k)
            copy.GetPrim().GetReferences().AddInternalReference("/Proto")
            copy.GetPrim().SetInstanceable(instanceable)
        stage.GetRootLayer().Save()
        out.append(_depth(path, tmp_path / f"o{instanceable}", "0:0"))
    _same(out[0], out[1], hits=0.01)


@pytest.mark.parametrize("damage, words", [
    ("index", "protoIndices[2] = 5: no such prototype"),
    ("nan", "positions[1] is inf or NaN"),
    ("empty", "has no mesh"),
    ("cycle", "a cycle of prototypes"),
    ("cycle2", "a cycle of prototypes (/World/PI -> /Other/PI2 -> /World/PI)"),
    ("length", "positions has 13 entries"),
    ("changing", "protoIndices change"),
])
def test_a_bad_point_instancer_is_one_line_and_exit_2(tmp_path, damage, words):
    data = _instance_data()
    path = tmp_path / "pi.usda"
    _instanced_stage(path, data)
    stage = Usd.Stage.Open(str(path))
    pi = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/PI"))
    proto = data[0].tolist()
    if damage == "index":
        proto[2] = 5
        pi.GetProtoIndicesAttr().Set(Vt.IntArray(proto))
    elif damage == "nan":
        pos = [Gf.Vec3f(*p) for p in data[1][0]]
        pos[1] = Gf.Vec3f(float("nan"), 0, 0)
        pi.GetPositionsAttr().Set(Vt.Vec3fArray(pos), 0)
    elif damage == "empty":
        UsdGeom.Xform.Define(stage, "/World/PI/Protos/Nothing")
        pi.GetPrototypesRel().AddTarget("/World/PI/Protos/Nothing")
        pi.GetProtoIndicesAttr().Set(Vt.IntArray([2] + proto[1:]))
    elif damage == "cycle":
        pi.GetPrototypesRel().AddTarget("/World")
        pi.GetProtoIndicesAttr().Set(Vt.IntArray([2] + proto[1:]))
    elif damage == "cycle2":                  # through a second instancer
        other = UsdGeom.PointInstancer.Define(stage, "/Other/PI2")
        other.GetPrototypesRel().SetTargets(["/World"])
        other.GetProtoIndicesAttr().Set(Vt.IntArray([0]))
        other.GetPositionsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(0, 0, 0)]))
        pi.GetPrototypesRel().AddTarget("/Other")
        pi.GetProtoIndicesAttr().Set(Vt.IntArray([2] + proto[1:]))
    elif damage == "length":
        pi.GetPositionsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*p) for p in data[1][10][:-1]]), 10)
    elif damage == "changing":
        pi.GetProtoIndicesAttr().Set(Vt.IntArray(proto), 0)
        pi.GetProtoIndicesAttr().Set(Vt.IntArray(proto[:-1]), 10)
    stage.Save()
    for command in ("check", "render"):
        res = CliRunner().invoke(main, [command, str(path), "-o", str(tmp_path / "o")] if command == "render"
                                 else [command, str(path)])
        assert res.exit_code == 2 and words in res.output, res.output
        assert len(res.output.strip().splitlines()) == 1


def test_the_instancers_display_colour_colours_each_copy(tmp_path):
    """primvars:displayColor on the instancer, one value per instance: each
    copy of a prototype without a material takes its own; a constant one
    colours them all; a wrong count is one line and exit 2."""
    from anim.scene import AnimatedScene
    data = _instance_data()
    path = tmp_path / "pi.usda"
    _instanced_stage(path, data)
    stage = Usd.Stage.Open(str(path))
    pi = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/PI"))
    rgb = np.random.default_rng(1).uniform(0, 1, (N, 3)).astype(np.float32)
    primvar = UsdGeom.PrimvarsAPI(pi).CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray,
                                                   UsdGeom.Tokens.vertex)
    primvar.Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, c)) for c in rgb]))
    stage.Save()
    scene = AnimatedScene(path)
    (obj,) = [o for o in scene.objects if o.name == "/World/PI"]
    rows = scene.material_table[scene.tri_material[obj.face_offset:obj.face_offset + len(obj.faces)]]
    # the copies in their layout: per prototype, per mesh, per instance using it
    got, start = {}, 0
    for mesh, root, ids, offset in obj.usd.meshes[0].blocks:
        for i in ids:
            got[int(i)] = rows[start:start + len(mesh.faces), :3]
            start += len(mesh.faces)
    assert len(got) == N and len(np.unique(rows[:, :3], axis=0)) == N
    for i, colours in got.items():
        np.testing.assert_allclose(colours, np.broadcast_to(rgb[i], colours.shape), rtol=1e-6)
    primvar.Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, c)) for c in rgb[:5]]))
    stage.Save()
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2 and "displayColor has 5 values for 14 instances" in res.output, res.output


def test_a_point_instancer_that_would_not_fit_is_refused(tmp_path, monkeypatch):
    import anim.memory
    _instanced_stage(tmp_path / "pi.usda", _instance_data())
    monkeypatch.setattr(anim.memory, "available_bytes", lambda: 50_000)
    res = CliRunner().invoke(main, ["check", str(tmp_path / "pi.usda")])
    assert res.exit_code == 2 and "point instancer /World/PI: 14 instances make" in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1


def test_skinned_characters_as_instanceable_references_render_as_plain_ones(tmp_path):
    """A skinned character (UsdSkel) referenced twice as instanceable prims:
    its skinning found through the instance proxies, the same depth as the
    same references without instancing, frame by frame."""
    from tests.usd_files import skinned_character
    skinned_character(tmp_path / "char.usda")
    out = []
    for instanceable in (True, False):
        path = tmp_path / f"two_{instanceable}.usda"
        stage = new_stage(path)
        cam = UsdGeom.Camera.Define(stage, "/Cam")
        cam.AddTranslateOp().Set(Gf.Vec3d(1.5, -9, 1))
        cam.AddRotateXOp().Set(90.0)
        cam.GetFocalLengthAttr().Set(18.0)
        for k in range(2):
            prim = stage.DefinePrim(f"/World/C{k}")                  # typeless: the reference's SkelRoot
            prim.GetReferences().AddReference("./char.usda", "/Char")
            UsdGeom.Xformable(prim).AddTranslateOp(opSuffix="place").Set(Gf.Vec3d(3.0 * k, 0, 0))
            prim.SetInstanceable(instanceable)
        stage.GetRootLayer().Save()
        out.append(_depth(path, tmp_path / f"o{instanceable}", "0:6"))
    _same(out[0], out[1], hits=0.01)
    assert not np.array_equal(np.isfinite(out[1][0]), np.isfinite(out[1][6]))          # they bend


def test_two_level_copies_take_their_display_colours(tmp_path):
    """primvars:displayColor per instance, traced two-level: each copy's
    colour is its own material (raycore/instancing/seen.py), so the frame
    equals the flattened one, colour for colour."""
    data = _instance_data()
    path = tmp_path / "pi.usda"
    _instanced_stage(path, data)
    stage = Usd.Stage.Open(str(path))
    pi = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/PI"))
    rgb = np.random.default_rng(2).uniform(0, 1, (N, 3)).astype(np.float32)
    UsdGeom.PrimvarsAPI(pi).CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray,
                                          UsdGeom.Tokens.vertex).Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, c))
                                                                                    for c in rgb]))
    UsdGeom.Xform.Define(stage, "/Sun")
    stage.Save()
    images = []
    for instancing in ("flatten", "two_level"):
        out = tmp_path / instancing
        res = CliRunner().invoke(main, ["render", str(path), "-o", str(out), "-q", "--res", "96x96", "--frames",
                                        "0:0", "--instancing", instancing])
        assert res.exit_code == 0, res.output
        names, pix, _ = read_exr(str(next(out.glob("*.exr"))))
        images.append(pix[..., [names.index(c) for c in "RGB"]])
    flat, two = images
    assert np.mean(np.any(flat > 0.01, axis=-1)) > 0.05
    assert np.mean(np.abs(flat - two).max(axis=-1) < 2e-3) >= 0.995
    assert len(np.unique(np.round(two.reshape(-1, 3), 2), axis=0)) > N


def test_instanceable_prims_two_level_match_their_flattened_frames(tmp_path):
    """Instanceable references (instance proxies) traced two-level: each
    prototype mesh read once, every instance root placing a copy (one of
    them moving, one with a material of its own bound above its
    prototype), against the same stage flattened: depth, ids (the
    flattened numbering, with a plain mesh between the instances) and colours."""
    path = tmp_path / "inst.usda"
    stage = new_stage(path)
    _camera(stage)
    _prototypes(stage, "/Proto")
    stage.GetPrimAtPath("/Proto").SetSpecifier(Sdf.SpecifierClass)
    red = UsdShade.Material.Define(stage, "/Looks/Red")
    shader = UsdShade.Shader.Define(stage, "/Looks/Red/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.9, 0.1, 0.1))
    red.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    rng = np.random.default_rng(6)
    for k in range(6):
        copy = UsdGeom.Xform.Define(stage, f"/World/C{k}")
        op = copy.AddTranslateOp()
        op.Set(Gf.Vec3d(*rng.uniform(-5, 5, 3) * [1, 0.6, 0.2]), 0)
        if k == 2:
            op.Set(Gf.Vec3d(0, -2, 0), 10)
        copy.AddRotateZOp().Set(float(rng.uniform(0, 360)))
        copy.GetPrim().GetReferences().AddInternalReference("/Proto")
        copy.GetPrim().SetInstanceable(True)
        if k == 4:
            UsdShade.MaterialBindingAPI.Apply(copy.GetPrim()).Bind(red)
        if k == 3:
            UsdGeom.Cube.Define(stage, "/World/Between")       # not a mesh: left out
            ground = UsdGeom.Mesh.Define(stage, "/World/Plain")
            ground.CreatePointsAttr([(-9, -4, -3), (9, -4, -3), (9, 4, -3), (-9, 4, -3)])
            ground.CreateFaceVertexCountsAttr([4])
            ground.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    stage.GetRootLayer().Save()
    from anim.scene import AnimatedScene
    scene = AnimatedScene(path, instancing="two_level")
    # the red copy is a group of its own, of one: flattened
    assert len(scene.instance_proto) == 5 * 2 and len(scene.proto_ranges) == 2
    frames = []
    for instancing in ("flatten", "two_level"):
        out = tmp_path / instancing
        res = CliRunner().invoke(main, ["render", str(path), "-o", str(out), "-q", "--res", "96x96", "--frames",
                                        "0:10", "--instancing", instancing, "--aov", "id"])
        assert res.exit_code == 0, res.output
        got = []
        for f in sorted(out.glob("*.exr")):
            names, pix, _ = read_exr(str(f))
            got.append((pix[..., names.index("Z")], pix[..., [names.index(c) for c in "RGB"]],
                        pix[..., names.index("id")]))
        frames.append(got)
    for (za, ca, ia), (zb, cb, ib) in zip(*frames):
        _same(za[None], zb[None], hits=0.02)
        assert np.mean(ia == ib) >= 0.999
        assert np.mean(np.abs(ca - cb).max(axis=-1) < 2e-3) >= 0.995


def _nested_data(seed=9):
    rng = np.random.default_rng(seed)
    outer = (rng.uniform(-4, 4, (4, 3)) * [1, 0.8, 0.2], rng.normal(size=(4, 4)), rng.uniform(0.6, 1.0, (4, 3)))
    inner = (rng.uniform(-1.5, 1.5, (3, 3)) * [1, 1, 0.3], rng.normal(size=(3, 4)), rng.uniform(0.3, 0.5, (3, 3)))
    return [(p, q / np.linalg.norm(q, axis=1, keepdims=True), s) for p, q, s in (outer, inner)]


def _trs(xf, p, q, s):
    xf.AddTranslateOp().Set(Gf.Vec3d(*map(float, p)))
    xf.AddOrientOp(UsdGeom.XformOp.PrecisionFloat).Set(Gf.Quatf(*map(float, q)))
    xf.AddScaleOp().Set(Gf.Vec3f(*map(float, s)))


def _pi(stage, path, protos, data):
    pos, q, scale = data
    pi = UsdGeom.PointInstancer.Define(stage, path)
    pi.GetPrototypesRel().SetTargets([Sdf.Path(p) for p in protos])
    pi.GetProtoIndicesAttr().Set(Vt.IntArray([0] * len(pos)))
    pi.GetPositionsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, p)) for p in pos]))
    pi.GetOrientationsfAttr().Set(Vt.QuatfArray([Gf.Quatf(*map(float, v)) for v in q]))
    pi.GetScalesAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, v)) for v in scale]))


@pytest.mark.parametrize("instancing", ["flatten", "two_level"])
def test_a_point_instancer_inside_a_prototype_renders_its_copies_of_copies(tmp_path, instancing):
    """Nested point instancers: an outer instancer whose prototype holds an
    inner instancer (and a mesh of its own); every outer copy shows the
    inner copies, placed by both instancers' transforms (usd-core's, each in
    its own space), against the same world written as nested Xforms over
    references."""
    outer, inner = _nested_data()
    path = tmp_path / "nested.usda"
    stage = new_stage(path)
    _camera(stage)
    UsdGeom.Xform.Define(stage, "/World/Outer/Protos/P")
    _prototypes(stage, "/World/Outer/Protos/P/Inner/Protos/Q")
    _pi(stage, "/World/Outer/Protos/P/Inner", ["/World/Outer/Protos/P/Inner/Protos/Q"], inner)
    pts, counts, idx = tube(n_around=6, n_along=2, length=1.0, radius=0.3)
    mesh(stage, "/World/Outer/Protos/P/Box", pts, counts, idx)
    _pi(stage, "/World/Outer", ["/World/Outer/Protos/P"], outer)
    stage.GetRootLayer().Save()
    flat_path = tmp_path / "flat.usda"
    flat = new_stage(flat_path)
    _camera(flat)
    _prototypes(flat, "/Q")
    flat.GetPrimAtPath("/Q").SetSpecifier(Sdf.SpecifierClass)
    for i in range(4):
        _trs(UsdGeom.Xform.Define(flat, f"/World/O{i}"), outer[0][i], outer[1][i], outer[2][i])
        for j in range(3):
            copy = UsdGeom.Xform.Define(flat, f"/World/O{i}/I{j}")
            _trs(copy, inner[0][j], inner[1][j], inner[2][j])
            copy.GetPrim().GetReferences().AddInternalReference("/Q")
        mesh(flat, f"/World/O{i}/Box", pts, counts, idx)
    flat.GetRootLayer().Save()
    got = _depth(path, tmp_path / "a", "0:0", instancing=instancing)
    want = _depth(flat_path, tmp_path / "b", "0:0")
    _same(got, want, hits=0.02)
