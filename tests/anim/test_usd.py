"""USD stages through usd-core (issue 22): skinned and blend-shaped meshes
against usd-core's own baked evaluation (UsdSkel.BakeSkinning, a separate
code path from the queries frustrace uses), time-sampled points and
transforms against numpy, a whole stage rendered with its own camera and
lights, and bad stages as one-line errors."""
import json
import math
import shutil

import numpy as np
import pytest
from click.testing import CliRunner

pxr = pytest.importorskip("pxr")
from pxr import Gf, Usd, UsdGeom, UsdSkel, Vt  # noqa: E402

from anim.scene import AnimatedScene  # noqa: E402
from cli.main import main  # noqa: E402
from usd_files import mesh, new_stage, shot, skinned_character, tube  # noqa: E402


def _scene(tmp_path, mesh_name, extra="", fps=24, end=10):
    path = tmp_path / "s.yaml"
    path.write_text(f"""version: 1
frames: {{start: 0, end: {end}, fps: {fps}}}
output: {{path: out/f_#.exr, resolution: [48, 48]}}
camera: {{eye: [1, -6, 1], look_at: [1, 0, 0], up: [0, 0, 1]}}
lights: [{{position: [2, -3, 6], intensity: 20}}]
objects:
  - name: thing
    mesh: {mesh_name}
{extra}""")
    return path


def _baked(path, tmp_path, times):
    """World-space points of /Char/Tube at each time code, by usd-core's
    BakeSkinning on a copy of the stage."""
    copy = tmp_path / "baked.usda"
    shutil.copy(path, copy)
    stage = Usd.Stage.Open(str(copy))
    assert UsdSkel.BakeSkinning(stage.Traverse(), Gf.Interval(min(times), max(times)))
    prim = stage.GetPrimAtPath("/Char/Tube")
    out = []
    for tc in times:
        pts = np.array(UsdGeom.Mesh(prim).GetPointsAttr().Get(tc), np.float64)
        m = np.array(UsdGeom.XformCache(tc).GetLocalToWorldTransform(prim)).reshape(4, 4)
        out.append(pts @ m[:3, :3] + m[3, :3])
    return out


def test_skinned_blend_shaped_mesh_matches_usd_cores_own_bake(tmp_path):
    skinned_character(tmp_path / "char.usda")
    scene = AnimatedScene(_scene(tmp_path, "char.usda"))
    assert not scene.objects[0].static and len(scene.faces) == 2 * 10 * 4
    times = [0, 3, 5, 7, 10]
    for tc, want in zip(times, _baked(tmp_path / "char.usda", tmp_path, times)):
        got = scene.vertices_at(tc / 24.0)                     # 24 time codes per second
        np.testing.assert_allclose(got, want, atol=2e-6)
    # the motion is real: the tip moved and bulged
    first, last = scene.vertices_at(0.0).copy(), scene.vertices_at(10 / 24).copy()
    assert np.abs(last - first).max() > 1.0


def test_time_sampled_points_and_transform_with_other_time_code_rate(tmp_path):
    """Points keyed at time codes 0 and 48, translate and rotateZ ops keyed
    too, 48 time codes per second: scene time t is time code 48 t."""
    stage = new_stage(tmp_path / "deform.usda", tcps=48.0, end=48)
    pts, counts, idx = tube(n_along=3)
    UsdGeom.Xform.Define(stage, "/Root")
    m = mesh(stage, "/Root/Blob", pts, counts, idx)
    moved = pts * np.array([1.0, 2.0, 0.5], np.float32)
    m.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(pts), 0)
    m.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(moved), 48)
    xf = UsdGeom.Xformable(stage.GetPrimAtPath("/Root"))
    t_op, r_op = xf.AddTranslateOp(), xf.AddRotateZOp()
    t_op.Set(Gf.Vec3d(0, 0, 0), 0)
    t_op.Set(Gf.Vec3d(2, 0, 0), 48)
    r_op.Set(0.0, 0)
    r_op.Set(90.0, 48)
    stage.GetRootLayer().Save()
    scene = AnimatedScene(_scene(tmp_path, "deform.usda"))
    for t in (0.0, 0.25, 0.5, 1.0, 1.5):
        s = min(t, 1.0)
        p = pts + s * (moved - pts)
        a = math.radians(90 * s)
        rot = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
        np.testing.assert_allclose(scene.vertices_at(t), p @ rot.T + [2 * s, 0, 0], atol=2e-6)


def test_prim_selects_a_subtree_and_static_meshes_are_static(tmp_path):
    shot(tmp_path / "shot.usda")
    scene = AnimatedScene(_scene(tmp_path, "shot.usda", "    prim: /World/Ground\n"))
    assert scene.objects[0].static and len(scene.faces) == 2
    scene = AnimatedScene(_scene(tmp_path, "shot.usda", "    prim: /World/Box\n"))
    assert not scene.objects[0].static


def test_whole_stage_renders_with_its_camera_lights_and_materials(tmp_path):
    shot(tmp_path / "shot.usda")
    res = CliRunner().invoke(main, ["check", str(tmp_path / "shot.usda")])
    assert res.exit_code == 0, res.output
    for words in ("upAxis Y", "metersPerUnit", "frames 0..2 at 24 fps", "camera /World/Cam", "3 light(s)",
                  "/World/Ground: 2 triangles, static", "/World/Box: 2 triangles, rigid"):
        assert words in res.output, (words, res.output)
    scene = AnimatedScene(tmp_path / "shot.usda")
    spec = scene.spec
    # camera: focal length 50, vertical aperture 24 -> 2 atan(12 / 50); 36 x 24 -> 3:2
    assert spec.camera.fov == pytest.approx(math.degrees(2 * math.atan(12 / 50)))
    assert tuple(spec.output.resolution) == (512, 341)
    kinds = sorted(light.type for light in spec.lights)
    assert kinds == ["area", "directional", "point"]
    point = next(light for light in spec.lights if light.type == "point")
    assert point.position == (2.0, 3.0, 4.0) and point.intensity == pytest.approx(10 * 2 * math.pi * 0.25)
    sun = next(light for light in spec.lights if light.type == "directional")
    np.testing.assert_allclose(sun.direction, [0, -1, 0], atol=1e-9)
    area = next(light for light in spec.lights if light.type == "area")
    assert area.intensity == pytest.approx(3.0 * 2.0)
    # the box slides from x = -1 to 1 over time codes 0..4 = frames 0..2
    for frame, x in ((0, -1.0), (1, 0.0), (2, 1.0)):
        v = scene.vertices_at(scene.time_of(frame))[4:]
        np.testing.assert_allclose(v[:, 0].mean(), x, atol=1e-6)
    out = tmp_path / "frames"
    res = CliRunner().invoke(main, ["render", str(tmp_path / "shot.usda"), "-o", str(out), "--res", "64x48",
                                    "--quiet"])
    assert res.exit_code == 0, res.output
    from raycore.images.image_io import read_exr
    names, pix, _ = read_exr(str(out / "frame_0001.exr"))
    z = pix[..., names.index("Z")]
    assert z[24, 32] == pytest.approx(6.0, rel=1e-5)            # the box at the centre, 6 in front
    r, g = pix[..., names.index("R")], pix[..., names.index("G")]
    assert r[44, 5] > 3 * g[44, 5] > 0                           # the red ground, lit


def test_camera_option_and_a_stage_without_camera_or_lights(tmp_path):
    shot(tmp_path / "shot.usda", camera=False, lights=False)
    res = CliRunner().invoke(main, ["check", str(tmp_path / "shot.usda")])
    assert res.exit_code == 0, res.output
    assert "no camera in the stage" in res.output and "a point light at the camera" in res.output
    spec = AnimatedScene(tmp_path / "shot.usda").spec
    assert [light.type for light in spec.lights] == ["point"] and spec.lights[0].position == spec.camera.eye
    res = CliRunner().invoke(main, ["check", str(tmp_path / "shot.usda"), "--camera", "/World/Nope"])
    assert res.exit_code == 2 and "--camera" in res.output and "/World/Nope" in res.output


def _check_line(path):
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2, res.output
    assert len(res.output.strip().splitlines()) == 1, res.output
    return res.output


def test_bad_stages_are_one_line_errors(tmp_path):
    (tmp_path / "broken.usda").write_text("#usda 1.0\ndef Mesh \"M\" {\n  point3f[] points = [(0, 0\n")
    out = _check_line(_scene(tmp_path, "broken.usda"))
    assert "objects.0.mesh" in out and "broken.usda" in out
    shot(tmp_path / "shot.usda")
    out = _check_line(_scene(tmp_path, "shot.usda", "    prim: /World/Nothing\n"))
    assert "objects.0.prim" in out and "/World/Nothing" in out
    stage = new_stage(tmp_path / "empty.usda")
    UsdGeom.Mesh.Define(stage, "/M")
    stage.GetRootLayer().Save()
    out = _check_line(_scene(tmp_path, "empty.usda"))
    assert "/M" in out and "no points" in out
    stage = new_stage(tmp_path / "unbound.usda")
    pts, counts, idx = tube(n_along=2)
    m = mesh(stage, "/Rig/Body", pts, counts, idx)
    b = UsdSkel.BindingAPI.Apply(m.GetPrim())
    b.CreateSkeletonRel().SetTargets(["/Rig/Missing"])
    b.CreateJointIndicesPrimvar(False, 1).Set(Vt.IntArray([0] * len(pts)))
    b.CreateJointWeightsPrimvar(False, 1).Set(Vt.FloatArray([1.0] * len(pts)))
    stage.GetRootLayer().Save()
    out = _check_line(_scene(tmp_path, "unbound.usda"))
    assert "/Rig/Body" in out and "/Rig/Missing" in out
    out = _check_line(_scene(tmp_path, "char.usda"))
    assert "not found" in out


def test_preview_surface_texture_with_face_varying_st_and_the_cluster_bundle(tmp_path):
    """A UsdUVTexture on diffuseColor: the image read sRGB, face-varying st
    splitting points only along the seam; the stage's files (a sublayer, the
    texture) travel in the cluster bundle."""
    from pxr import Sdf, UsdShade
    from anim.render.cluster import referenced_files
    from anim.render.settings import shading_of
    from raycore.images.image_io import _write_8bit
    _write_8bit(str(tmp_path / "checker.png"), np.array([[[255, 255, 255], [0, 0, 0]]], np.uint8))
    layer = new_stage(tmp_path / "geo.usda")
    pts = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]]
    m = mesh(layer, "/Geo/Strip", pts, [4, 4], [0, 1, 4, 3, 1, 2, 5, 4])
    st = UsdGeom.PrimvarsAPI(m.GetPrim()).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                        UsdGeom.Tokens.faceVarying)
    # the second quad's st restarts at 0: points 1 and 4 are split along that seam
    st.Set(Vt.Vec2fArray([(0, 0), (1, 0), (1, 1), (0, 1), (0, 0), (1, 0), (1, 1), (0, 1)]))
    from usd_files import preview_material
    mat = preview_material(layer, "/Geo/Looks/Check", (1, 1, 1), texture="checker.png")
    UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(mat)
    layer.GetRootLayer().Save()
    top = new_stage(tmp_path / "top.usda")
    top.GetRootLayer().subLayerPaths.append("geo.usda")
    top.GetRootLayer().Save()
    scene = AnimatedScene(_scene(tmp_path, "top.usda"))
    assert scene.n_vertices == 8 and scene.faces.shape == (4, 3)          # 6 points, 2 split at the seam
    corner_uv = {(tuple(np.round(scene.vertices_at(0.0)[v], 6)), tuple(scene.uvs[v])) for v in scene.faces.ravel()}
    assert ((1.0, 0.0, 0.0), (1.0, 0.0)) in corner_uv and ((1.0, 0.0, 0.0), (0.0, 0.0)) in corner_uv
    shading = shading_of(scene)
    assert shading.tex_info.tolist() == [[0, 2, 1]]
    np.testing.assert_allclose(shading.tex_data[:6], [1, 1, 1, 0, 0, 0], atol=1e-6)
    refs = {ref for _, ref in referenced_files(scene)}
    assert {"s.yaml", "top.usda", "geo.usda", "checker.png"} <= refs


def test_meshes_that_ask_for_subdivision_are_one_warning(tmp_path):
    shot(tmp_path / "shot.usda")           # its meshes leave subdivisionScheme unset: catmullClark
    res = CliRunner().invoke(main, ["check", str(tmp_path / "shot.usda")])
    assert res.exit_code == 0
    lines = [line for line in res.output.splitlines() if "subdivision" in line]
    assert len(lines) == 1 and "2 USD mesh(es)" in lines[0] and "/World/Ground" in lines[0]
    stage = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    for path in ("/World/Ground", "/World/Box"):
        UsdGeom.Mesh(stage.GetPrimAtPath(path)).CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    stage.GetRootLayer().Save()
    res = CliRunner().invoke(main, ["check", str(tmp_path / "shot.usda")])
    assert res.exit_code == 0 and "subdivision" not in res.output


def test_a_constant_display_colour_is_the_colour_without_a_material(tmp_path):
    stage = new_stage(tmp_path / "plain.usda")
    pts, counts, idx = tube(n_along=2)
    m = mesh(stage, "/Green", pts, counts, idx)
    m.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(Vt.Vec3fArray([Gf.Vec3f(0.1, 0.7, 0.2)]))
    mesh(stage, "/Plain", pts + np.float32(3), counts, idx)
    stage.GetRootLayer().Save()
    scene = AnimatedScene(_scene(tmp_path, "plain.usda"))
    table = scene.material_table[scene.tri_material]
    n = len(scene.faces) // 2
    np.testing.assert_allclose(table[:n, :3], [[0.1, 0.7, 0.2]] * n, rtol=1e-6)
    np.testing.assert_allclose(table[n:, :3], [[0.8, 0.8, 0.8]] * n)          # the default material


def test_a_usdz_package_renders_with_the_texture_inside_it(tmp_path):
    from pxr import Sdf, UsdShade, UsdUtils
    from anim.render.settings import shading_of
    from raycore.images.image_io import _write_8bit
    from usd_files import preview_material
    _write_8bit(str(tmp_path / "tex.png"), np.array([[[255, 0, 0], [0, 255, 0]]], np.uint8))
    stage = new_stage(tmp_path / "loose.usda")
    m = mesh(stage, "/M", [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [4], [0, 1, 2, 3])
    UsdGeom.PrimvarsAPI(m.GetPrim()).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                   UsdGeom.Tokens.vertex).Set(Vt.Vec2fArray(
                                                       [(0, 0), (1, 0), (1, 1), (0, 1)]))
    UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(preview_material(stage, "/Looks/T", (1, 1, 1),
                                                                         texture="tex.png"))
    stage.GetRootLayer().Save()
    assert UsdUtils.CreateNewUsdzPackage(str(tmp_path / "loose.usda"), str(tmp_path / "pkg.usdz"))
    (tmp_path / "tex.png").unlink()                    # only the copy inside the package is left
    scene = AnimatedScene(_scene(tmp_path, "pkg.usdz"))
    shading = shading_of(scene)
    np.testing.assert_allclose(shading.tex_data[:6], [1, 0, 0, 0, 1, 0], atol=1e-6)
    from anim.render.cluster import referenced_files
    assert {ref for _, ref in referenced_files(scene)} == {"s.yaml", "pkg.usdz"}


def test_an_orthographic_camera_is_refused_in_one_line(tmp_path):
    stage = shot(tmp_path / "shot.usda")
    UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam")).CreateProjectionAttr(UsdGeom.Tokens.orthographic)
    stage.GetRootLayer().Save()
    out = _check_line(tmp_path / "shot.usda")
    assert "/World/Cam" in out and "orthographic" in out


def test_the_cameras_lens_and_shutter_become_depth_of_field_and_motion_blur(tmp_path):
    """fStop and focusDistance make the thin lens (diameter focalLength /
    fStop, focalLength in tenths of a unit); shutter:open/close (frames
    around the frame time) the shutter; unauthored, a pinhole and none."""
    shot(tmp_path / "shot.usda")
    plain = AnimatedScene(tmp_path / "shot.usda").spec
    assert plain.camera.aperture_radius == 0 and plain.render.motion_blur.shutter == 0
    stage = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam"))
    cam.CreateFStopAttr(2.5)
    cam.CreateFocusDistanceAttr(6.0)
    cam.CreateShutterOpenAttr(-0.25)
    cam.CreateShutterCloseAttr(0.25)
    stage.Save()
    res = CliRunner().invoke(main, ["check", str(tmp_path / "shot.usda")])
    assert res.exit_code == 0, res.output
    assert "depth of field from the camera: f/2.5" in res.output and "shutter -0.25..0.25 frames" in res.output
    spec = AnimatedScene(tmp_path / "shot.usda").spec
    assert spec.camera.aperture_radius == pytest.approx(50 * 0.1 / (2 * 2.5))
    assert spec.camera.focus_distance == 6.0
    assert (spec.render.motion_blur.shutter, spec.render.motion_blur.position) == (0.5, "center")
    out = tmp_path / "frames"
    res = CliRunner().invoke(main, ["render", str(tmp_path / "shot.usda"), "-o", str(out), "--res", "32x24",
                                    "--spp", "4", "--frames", "1:1", "--quiet"])
    assert res.exit_code == 0, res.output
    frame = json.loads((out / "stats.json").read_text())["frames"][0]
    assert frame["time_samples"] == 4 and frame["lens_samples"] == 4


def _cube(stage, path, normals=None):
    """A unit cube of 8 shared points and 6 quads; normals: None, or
    (interpolation, values) authored on it."""
    pts = [[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    m = mesh(stage, path, pts, [4] * 6, [i for q in quads for i in q])
    m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    if normals is not None:
        interp, values = normals
        m.CreateNormalsAttr(Vt.Vec3fArray([Gf.Vec3f(*n) for n in values]))
        m.SetNormalsInterpolation(interp)
    return m, quads


def _smooth_normals(scene):
    """The renderer's vertex normals of the scene's rest pose."""
    from raycore.geometry.mesh import vertex_face_csr, vertex_normals
    verts = scene.vertices_at(0.0).astype(np.float32)
    tri = np.ascontiguousarray(verts[scene.faces].reshape(-1, 9))
    start, faces = vertex_face_csr(scene.faces, len(verts))
    normals = np.empty((len(verts), 3), np.float32)
    vertex_normals(tri, start, faces, normals)
    return verts, normals


@pytest.mark.parametrize("interp", ["faceVarying", "uniform"])
def test_authored_face_normals_give_a_cube_hard_edges(tmp_path, interp):
    """A cube whose authored normals are the faces' own (faceVarying or
    uniform): every corner's smooth normal is its face's normal, not the
    average of three faces (the smooth blob it shaded as); without authored
    normals it stays one shared point a corner."""
    stage = new_stage(tmp_path / "cube.usda")
    face_n = [[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]]
    values = [n for n in face_n for _ in range(4)] if interp == "faceVarying" else face_n
    _cube(stage, "/Cube", (interp, values))
    _cube(stage, "/Plain")
    stage.GetRootLayer().Save()
    scene = AnimatedScene(_scene(tmp_path, "cube.usda", "    prim: /Cube\n"))
    assert scene.n_vertices == 24 and scene.faces.shape == (12, 3)
    verts, normals = _smooth_normals(scene)
    for tri in scene.faces:
        a, b, c = verts[tri].astype(np.float64)
        n = np.cross(b - a, c - a)
        n /= np.linalg.norm(n)
        np.testing.assert_allclose(normals[tri], np.repeat(n[None], 3, axis=0), atol=1e-6)
    plain = AnimatedScene(_scene(tmp_path, "cube.usda", "    prim: /Plain\n"))
    assert plain.n_vertices == 8


def test_a_concave_polygon_is_ear_clipped_and_a_convex_one_keeps_its_fan(tmp_path):
    """An L-shaped hexagon: its triangles cover the L exactly (area 3, none
    outside it), where a fan from its first corner covered the notch; a
    convex pentagon keeps the fan from its first corner."""
    from anim.io.polygons import fan, triangulate
    stage = new_stage(tmp_path / "l.usda")
    ell = [[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]]
    mesh(stage, "/L", ell, [6], [0, 1, 2, 3, 4, 5])
    stage.GetRootLayer().Save()
    scene = AnimatedScene(_scene(tmp_path, "l.usda"))
    verts = scene.vertices_at(0.0).astype(np.float64)
    tris = verts[scene.faces]
    areas = 0.5 * np.abs(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])[:, 2])
    assert len(tris) == 4 and abs(areas.sum() - 3.0) < 1e-9
    centroids = tris.mean(axis=1)
    assert not np.any((centroids[:, 0] > 1) & (centroids[:, 1] > 1))        # nothing in the notch
    pentagon = np.array([[np.cos(a), np.sin(a), 0] for a in np.linspace(0, 2 * np.pi, 5, endpoint=False)])
    faces, corner, poly = triangulate([5], np.arange(5), pentagon)
    expected, _ = fan(np.array([5]), np.array([0]))
    assert np.array_equal(corner, expected) and np.array_equal(faces, expected)


def test_animated_visibility_hides_a_mesh_at_the_frames_it_is_invisible(tmp_path):
    """visibility time samples {0: inherited, 6: invisible}: the mesh is hit
    at frame 0 and at no pixel at frame 12; a mesh hidden from the start
    that shows up later is there when it shows up."""
    from anim.render.renderer import SceneRenderer
    from anim.render.settings import config_of, shading_of
    stage = new_stage(tmp_path / "vis.usda", end=12)
    pts, counts, idx = tube()
    mesh(stage, "/Gone", pts, counts, idx)
    late = mesh(stage, "/Late", np.asarray(pts) + [0, 0, 1.5], counts, idx)
    vis = UsdGeom.Imageable(stage.GetPrimAtPath("/Gone")).CreateVisibilityAttr()
    vis.Set(UsdGeom.Tokens.inherited, 0)
    vis.Set(UsdGeom.Tokens.invisible, 6)
    late_vis = UsdGeom.Imageable(late.GetPrim()).CreateVisibilityAttr()
    late_vis.Set(UsdGeom.Tokens.invisible, 0)
    late_vis.Set(UsdGeom.Tokens.inherited, 6)
    stage.GetRootLayer().Save()
    scene = AnimatedScene(_scene(tmp_path, "vis.usda", end=12))
    renderer = SceneRenderer(scene, config_of(scene), shading_of(scene))
    n_gone = 10 * 5

    def hits(frame):
        _, result = renderer.render(scene.time_of(frame))
        return np.isfinite(result.z).sum()
    assert not scene.objects[0].static
    v0, v12 = scene.vertices_at(scene.time_of(0)).copy(), scene.vertices_at(scene.time_of(12)).copy()
    assert np.ptp(v12[:n_gone], axis=0).max() == 0 and np.ptp(v0[:n_gone], axis=0).max() > 0    # collapsed
    assert np.ptp(v0[n_gone:], axis=0).max() == 0 and np.ptp(v12[n_gone:], axis=0).max() > 0
    assert hits(0) > 0 and hits(12) > 0


def test_authored_but_unsupported_usd_is_named(tmp_path):
    """A missing texture file is exit 2 naming the shader and the file (it
    rendered grey); holeIndices are a warning naming the mesh (they render
    solid); topology authored only as time samples is named as such."""
    from pxr import UsdShade
    stage = new_stage(tmp_path / "tex.usda")
    pts, counts, idx = tube(n_along=2)
    m = mesh(stage, "/M", pts, counts, idx)
    from usd_files import preview_material
    UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(preview_material(stage, "/Looks/Missing", (1, 1, 1),
                                                                         texture="nowhere.png"))
    stage.GetRootLayer().Save()
    out = _check_line(_scene(tmp_path, "tex.usda"))
    assert "texture file not found" in out and "nowhere.png" in out and "/Looks/Missing/Tex" in out
    stage = new_stage(tmp_path / "holes.usda")
    mesh(stage, "/Holey", pts, counts, idx).CreateHoleIndicesAttr([0, 1])
    stage.GetRootLayer().Save()
    res = CliRunner().invoke(main, ["check", str(_scene(tmp_path, "holes.usda"))])
    assert res.exit_code == 0 and "holeIndices" in res.output and "/Holey" in res.output
    stage = new_stage(tmp_path / "sampled.usda")
    sampled = UsdGeom.Mesh.Define(stage, "/Sampled")
    sampled.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(pts, np.float32)))
    sampled.CreateFaceVertexCountsAttr().Set(list(counts), 0)
    sampled.CreateFaceVertexIndicesAttr().Set(list(idx), 0)
    stage.GetRootLayer().Save()
    out = _check_line(_scene(tmp_path, "sampled.usda"))
    assert "time samples" in out and "/Sampled" in out


def test_check_strict_rejects_a_usd_reference_that_leaves_the_scenes_folder(tmp_path):
    """A stage that references a layer outside the scene's folder
    (@../props/props.usda@) is a warning, and an error under --strict, as a
    scene file's mesh outside its folder is."""
    (tmp_path / "props").mkdir()
    (tmp_path / "shot").mkdir()
    props = new_stage(tmp_path / "props" / "props.usda")
    pts, counts, idx = tube(n_along=2)
    mesh(props, "/Prop", pts, counts, idx)
    props.GetRootLayer().Save()
    top = new_stage(tmp_path / "shot" / "shot.usda")
    top.DefinePrim("/Prop").GetReferences().AddReference("../props/props.usda", "/Prop")
    top.GetRootLayer().Save()
    path = _scene(tmp_path / "shot", "shot.usda")
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 0 and "props.usda" in res.output and "outside" in res.output, res.output
    res = CliRunner().invoke(main, ["check", "--strict", str(path)])
    assert res.exit_code == 2 and "objects.0.mesh" in res.output and "props.usda" in res.output, res.output


def test_frames_past_a_stages_range_are_warned_and_aovs_can_be_asked_for(tmp_path):
    """A whole stage rendered past its time codes (frames 0..2) says its
    meshes hold still there; `--aov` asks a stage (which has no output.aovs)
    for extra channels."""
    shot(tmp_path / "shot.usda")
    out = tmp_path / "frames"
    res = CliRunner().invoke(main, ["render", str(tmp_path / "shot.usda"), "-o", str(out), "--res", "32x24",
                                    "--frames", "2:4", "--aov", "N,id", "-q"])
    assert res.exit_code == 0, res.output
    assert "time codes only cover 0..0.0833333" in res.stderr and "frames 2..4" in res.stderr, res.stderr
    from raycore.images.image_io import read_exr
    names, _, _ = read_exr(str(out / "frame_0004.exr"))
    assert {"N.X", "N.Y", "N.Z", "id"} <= set(names)
    res = CliRunner().invoke(main, ["render", str(tmp_path / "shot.usda"), "-o", str(out), "--aov", "Q", "-q"])
    assert res.exit_code == 2 and "--aov" in res.output
    res = CliRunner().invoke(main, ["render", str(tmp_path / "shot.usda"), "-o", str(tmp_path / "in"),
                                    "--res", "32x24", "--frames", "0:2", "-q"])
    assert res.exit_code == 0 and "time codes" not in res.stderr


def test_a_rect_light_lights_only_the_side_it_faces(tmp_path):
    """USD's RectLight emits along its -Z only: turned to face away from the
    scene it lights nothing (it lit both sides), and facing it, a point
    straight below gets its full intensity, one off to the side less (the
    cosine of a Lambertian emitter)."""
    from anim.render.renderer import SceneRenderer
    from anim.render.settings import config_of, shading_of
    from pxr import UsdLux
    results = {}
    for facing in ("down", "up"):
        stage = new_stage(tmp_path / f"rect_{facing}.usda", up="Y", end=0)
        mesh(stage, "/Floor", [[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], [4], [0, 3, 2, 1])
        light = UsdLux.RectLight.Define(stage, "/Light")
        light.CreateIntensityAttr(20.0)
        light.CreateWidthAttr(0.2)
        light.CreateHeightAttr(0.2)
        xf = UsdGeom.Xformable(light.GetPrim())
        xf.AddTranslateOp().Set(Gf.Vec3d(0, 2, 0))
        xf.AddRotateXOp().Set(-90.0 if facing == "down" else 90.0)       # -Z turned to -Y (down) or +Y
        cam = UsdGeom.Camera.Define(stage, "/Cam")
        UsdGeom.Xformable(cam.GetPrim()).AddTranslateOp().Set(Gf.Vec3d(0, 8, 0))
        UsdGeom.Xformable(cam.GetPrim()).AddRotateXOp().Set(-90.0)
        stage.GetRootLayer().Save()
        scene = AnimatedScene(tmp_path / f"rect_{facing}.usda")
        assert scene.spec.lights[0].sides == 1
        cfg = config_of(scene, width=33, height=33, ambient=0.0)
        _, result = SceneRenderer(scene, cfg, shading_of(scene)).render(0.0)
        results[facing] = result.rgba[..., :3].astype(np.float64).sum(axis=-1)
    down, up = results["down"], results["up"]
    assert up.max() == 0.0 and down[16, 16] > 0
    # a small light 2 above the floor, seen by a pixel 6 columns aside at a
    # distance r: the floor's cosine and the emitter's are both 2 / r, so the
    # light falls as 16 / r^4 against the centre (a two-sided emitter: 8 / r^3)
    h = np.tan(np.radians(scene.spec.camera.fov) / 2)
    x = 8 * (2 * (22 + 0.5) / 33 - 1) * h
    r = np.hypot(2.0, x)
    assert down[16, 22] / down[16, 16] == pytest.approx(16 / r ** 4, rel=0.03), (down[16, 22] / down[16, 16], r)
