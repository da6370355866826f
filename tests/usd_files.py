"""Small USD stages written by the tests themselves with usd-core's API."""
import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, UsdSkel, Vt


def tube(n_around=10, n_along=5, length=2.0, radius=0.3):
    """An open cylinder along x from 0 to length: (points, counts, indices) as quads."""
    a = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    xs = np.linspace(0, length, n_along)
    pts = np.array([[x, radius * np.cos(t), radius * np.sin(t)] for x in xs for t in a], np.float32)
    idx = []
    for i in range(n_along - 1):
        for j in range(n_around):
            p, q = i * n_around + j, i * n_around + (j + 1) % n_around
            idx += [p, q, q + n_around, p + n_around]
    return pts, [4] * (len(idx) // 4), idx


def new_stage(path, up="Z", start=0, end=10, tcps=24.0, fps=24.0):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up == "Z" else UsdGeom.Tokens.y)
    stage.SetStartTimeCode(start)
    stage.SetEndTimeCode(end)
    stage.SetTimeCodesPerSecond(tcps)
    stage.SetFramesPerSecond(fps)
    return stage


def mesh(stage, path, pts, counts, idx):
    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(pts, np.float32)))
    m.CreateFaceVertexCountsAttr(list(counts))
    m.CreateFaceVertexIndicesAttr(list(idx))
    return m


def skinned_character(path):
    """As Blender writes a rigged character: a SkelRoot (moved and turned)
    with a two-joint Skeleton, a SkelAnimation (the elbow turning 90 degrees
    about z over time codes 0..10, a blend-shape weight 0 -> 1) and a
    skinned tube with a 'bulge' BlendShape on its tip ring."""
    stage = new_stage(path)
    root = UsdSkel.Root.Define(stage, "/Char")
    xf = UsdGeom.Xformable(root.GetPrim())
    xf.AddTranslateOp().Set(Gf.Vec3d(0.5, -0.25, 0.1))
    xf.AddRotateZOp().Set(20.0)
    skel = UsdSkel.Skeleton.Define(stage, "/Char/Skel")
    joints = ["root", "root/elbow"]
    skel.CreateJointsAttr(joints)
    elbow = Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(1, 0, 0))
    skel.CreateBindTransformsAttr([Gf.Matrix4d(1), elbow])
    skel.CreateRestTransformsAttr([Gf.Matrix4d(1), elbow])
    anim = UsdSkel.Animation.Define(stage, "/Char/Skel/Anim")
    anim.CreateJointsAttr(joints)
    anim.CreateTranslationsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 0, 0), Gf.Vec3f(1, 0, 0)]))
    anim.CreateScalesAttr(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1), Gf.Vec3h(1, 1, 1)]))
    rot = anim.CreateRotationsAttr()
    for tc, deg in ((0, 0.0), (10, 90.0)):
        q = Gf.Rotation(Gf.Vec3d(0, 0, 1), deg).GetQuat()
        rot.Set(Vt.QuatfArray([Gf.Quatf(1, 0, 0, 0), Gf.Quatf(q)]), tc)
    anim.CreateBlendShapesAttr(["bulge"])
    w = anim.CreateBlendShapeWeightsAttr()
    w.Set(Vt.FloatArray([0.0]), 0)
    w.Set(Vt.FloatArray([1.0]), 10)
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    pts, counts, idx = tube()
    m = mesh(stage, "/Char/Tube", pts, counts, idx)
    b = UsdSkel.BindingAPI.Apply(m.GetPrim())
    b.CreateSkeletonRel().SetTargets([skel.GetPath()])
    w_elbow = np.clip(pts[:, 0] - 0.5, 0, 1)                     # blended across the middle
    b.CreateJointIndicesPrimvar(False, 2).Set(Vt.IntArray([j for _ in pts for j in (0, 1)]))
    b.CreateJointWeightsPrimvar(False, 2).Set(Vt.FloatArray([float(x) for we in w_elbow for x in (1 - we, we)]))
    b.CreateGeomBindTransformAttr(Gf.Matrix4d(1))
    tip = np.nonzero(pts[:, 0] > 1.9)[0]
    shape = UsdSkel.BlendShape.Define(stage, "/Char/Tube/bulge")
    offsets = pts[tip].copy()
    offsets[:, 0] = 0
    shape.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(0.8 * offsets))
    shape.CreatePointIndicesAttr(Vt.IntArray([int(i) for i in tip]))
    b.CreateBlendShapesAttr(["bulge"])
    b.CreateBlendShapeTargetsRel().SetTargets([shape.GetPath()])
    stage.GetRootLayer().Save()
    return stage


def preview_material(stage, path, colour, roughness=0.5, metallic=0.0, texture=None):
    """A UsdPreviewSurface material; texture: an image file name for diffuseColor."""
    mat = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, f"{path}/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(roughness)
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(metallic)
    diffuse = shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f)
    if texture is None:
        diffuse.Set(Gf.Vec3f(*colour))
    else:
        reader = UsdShade.Shader.Define(stage, f"{path}/St")
        reader.CreateIdAttr("UsdPrimvarReader_float2")
        reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("st")
        tex = UsdShade.Shader.Define(stage, f"{path}/Tex")
        tex.CreateIdAttr("UsdUVTexture")
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(texture)
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
        diffuse.ConnectToSource(tex.ConnectableAPI(), "rgb")
    mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return mat


def shot(path, camera=True, lights=True):
    """A whole shot, Y up: a red static ground, a time-sampled box sliding
    along x over time codes 0..4 (48 per second, 24 fps: frames 0..2), a
    camera 6 units in front looking down -z, and a sphere, a distant and a
    rect light."""
    stage = new_stage(path, up="Y", start=0, end=4, tcps=48.0, fps=24.0)
    UsdGeom.Xform.Define(stage, "/World")
    ground = mesh(stage, "/World/Ground", [[-4, -1, -4], [4, -1, -4], [4, -1, 4], [-4, -1, 4]], [4], [0, 3, 2, 1])
    red = preview_material(stage, "/World/Looks/Red", (0.8, 0.1, 0.1))
    UsdShade.MaterialBindingAPI.Apply(ground.GetPrim()).Bind(red)
    box = mesh(stage, "/World/Box", [[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], [4],
               [0, 1, 2, 3])
    UsdGeom.Xformable(box.GetPrim()).AddTranslateOp().Set(Gf.Vec3d(-1, 0, 0), 0)
    UsdGeom.Xformable(box.GetPrim()).GetOrderedXformOps()[0].Set(Gf.Vec3d(1, 0, 0), 4)
    if camera:
        cam = UsdGeom.Camera.Define(stage, "/World/Cam")
        cam.AddTranslateOp().Set(Gf.Vec3d(0, 0, 6))
        cam.CreateFocalLengthAttr(50.0)
        cam.CreateVerticalApertureAttr(24.0)
        cam.CreateHorizontalApertureAttr(36.0)
    if lights:
        sphere = UsdLux.SphereLight.Define(stage, "/World/Key")
        sphere.AddTranslateOp().Set(Gf.Vec3d(2, 3, 4))
        sphere.CreateRadiusAttr(0.5)
        sphere.CreateIntensityAttr(10.0)
        sphere.CreateExposureAttr(1.0)
        sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
        sun.AddRotateXOp().Set(-90.0)                # shines along -y
        sun.CreateIntensityAttr(0.5)
        rect = UsdLux.RectLight.Define(stage, "/World/Fill")
        rect.AddTranslateOp().Set(Gf.Vec3d(0, 4, 0))
        rect.CreateWidthAttr(2.0)
        rect.CreateHeightAttr(1.0)
        rect.CreateIntensityAttr(3.0)
    stage.GetRootLayer().Save()
    return stage
