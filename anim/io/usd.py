"""USD stages (.usd, .usda, .usdc, .usdz) through Pixar's usd-core.

Two uses:
  * `mesh: shot.usd` (with `prim: /path`): every UsdGeomMesh under the prim
    as one frustrace object (UsdObject);
  * `frustrace render shot.usd`: the whole stage as a scene (scene_of_stage):
    a frustrace object per mesh, so that static meshes are placed once; the
    stage's camera, UsdLux lights, frame range and frame rate.

Motion is evaluated by usd-core itself, not re-implemented: time-sampled
points and transforms through UsdGeom (XformCache), skinning and blend
shapes through UsdSkel (Cache, SkelQuery, SkinningQuery, BlendShapeQuery).
Scene time t (seconds) is the stage's time code t * timeCodesPerSecond.
Coordinates stay as authored: no up-axis or unit conversion.
"""
import math
from pathlib import Path

import numpy as np

from anim.errors import SceneError
from anim.io.polygons import split_at_seams, triangulate
from anim.instances import two_level
from anim.io.usd_instancer import PointInstancer, check_cycles
from anim.io.usd_proxies import ProxyInstances, instance_root, proxy_groups
from anim.materials import DEFAULT_MATERIAL, pbr_material

USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
_STAGES = {}          # resolved path -> (mtime, Stage, UsdSkel.Cache): one open per file
_SKINNED = {}         # id(stage) -> (stage, its skinned meshes)


def is_usd(name) -> bool:
    return str(name).lower().endswith(USD_SUFFIXES)


def _pxr(scene_path, key):
    try:
        from pxr import Usd, UsdGeom, UsdLux, UsdShade, UsdSkel, Gf, Vt    # noqa: F401
    except ImportError:
        raise SceneError(scene_path, key, "reading USD needs usd-core: pip install usd-core") from None
    import pxr
    return pxr


def open_stage(path, scene_path, key):
    """(stage, skel cache) of a USD file, opened once per file and change."""
    pxr = _pxr(scene_path, key)
    path = Path(path)
    if not path.is_file():
        raise SceneError(scene_path, key, f"USD file not found: {path}")
    resolved = str(path.resolve())
    mtime = path.stat().st_mtime_ns
    cached = _STAGES.get(resolved)
    if cached is not None and cached[0] == mtime:
        return cached[1], cached[2]
    try:
        stage = pxr.Usd.Stage.Open(resolved)
    except Exception as exc:                         # pxr.Tf.ErrorException
        problem = " ".join(str(exc).split())
        raise SceneError(scene_path, key, f"cannot open USD stage {path.name}: {problem[:300]}") from None
    if stage is None:
        raise SceneError(scene_path, key, f"cannot open USD stage {path.name}")
    check_cycles(stage, pxr, scene_path, key)
    _STAGES[resolved] = (mtime, stage, pxr.UsdSkel.Cache())
    return stage, _STAGES[resolved][2]


def _matrix(m) -> np.ndarray:
    """A Gf.Matrix4d as a numpy (4, 4); USD multiplies row vectors: p' = p M."""
    return np.array(m, np.float64).reshape(4, 4)


def _apply(points, m):
    return points @ m[:3, :3] + m[3, :3]


def _triangulate(counts, indices, points, path, scene_path, key):
    """Triangles of polygons (fans, ear clipping for concave ones:
    polygons.py); (faces (n_t, 3), corner (n_t, 3) index into
    faceVertexIndices, polygon of each triangle)."""
    counts = np.asarray(counts, np.int64)
    indices = np.asarray(indices, np.int64)
    if counts.sum() != len(indices) or np.any(counts < 0):
        raise SceneError(scene_path, key, f"{path}: faceVertexCounts do not add up to faceVertexIndices")
    if len(indices) and (indices.max() >= len(points) or indices.min() < 0):
        raise SceneError(scene_path, key, f"{path}: a face index is beyond its {len(points)} points")
    return triangulate(counts, indices, points)


def _topology(mesh, path, scene_path, key):
    """(faceVertexCounts, faceVertexIndices) at the default time; topology
    authored only as time samples is named as such (it is not read)."""
    counts_attr, indices_attr = mesh.GetFaceVertexCountsAttr(), mesh.GetFaceVertexIndicesAttr()
    counts, indices = counts_attr.Get(), indices_attr.Get()
    if counts is None or indices is None:
        if counts_attr.GetNumTimeSamples() or indices_attr.GetNumTimeSamples():
            raise SceneError(scene_path, key, f"{path}: its topology (faceVertexCounts, faceVertexIndices) is "
                                              "authored only as time samples; time-varying topology is not "
                                              "supported: author it at the default time")
        raise SceneError(scene_path, key, f"{path}: the mesh has no faces")
    return counts, indices


def _authored_normals(prim, corner, poly, pxr):
    """Per-corner normal ids (n_t, 3) where the mesh's authored normals
    (primvars:normals, else normals) differ between the corners of one point
    (faceVarying or uniform: hard edges), else None. The points are split
    along those seams; the smooth normal within a seam is the geometry's."""
    api = pxr.UsdGeom.PrimvarsAPI(prim)
    mesh = pxr.UsdGeom.Mesh(prim)
    if api.HasPrimvar("normals") and api.GetPrimvar("normals").HasAuthoredValue():
        primvar = api.GetPrimvar("normals")
        values, interp = primvar.ComputeFlattened(), primvar.GetInterpolation()
    else:
        values, interp = mesh.GetNormalsAttr().Get(), mesh.GetNormalsInterpolation()
    if values is None or len(values) == 0 or interp not in ("faceVarying", "uniform"):
        return None
    normals = np.asarray(values, np.float64).reshape(-1, 3)
    # a normal id per distinct direction (rounded: the same normal written twice)
    _, ids = np.unique(np.round(normals, 6), axis=0, return_inverse=True)
    ids = ids.reshape(-1)
    if interp == "uniform" and len(normals) == int(poly.max(initial=-1)) + 1:
        return np.repeat(ids[poly][:, None], 3, axis=1)        # one normal a polygon
    if interp == "faceVarying" and len(normals) == int(corner.max(initial=-1)) + 1:
        return ids[corner]
    return None


class _Mesh:
    """One UsdGeomMesh: topology, and how to evaluate its points at a time code."""

    def __init__(self, prim, skinning, scene_path, key):
        pxr = _pxr(scene_path, key)
        UsdGeom = pxr.UsdGeom
        self.prim, self.path = prim, str(prim.GetPath())
        mesh = UsdGeom.Mesh(prim)
        self.points_attr = mesh.GetPointsAttr()
        rest = self.points_attr.Get(pxr.Usd.TimeCode.EarliestTime())
        if rest is None or len(rest) == 0:
            raise SceneError(scene_path, key, f"{self.path}: the mesh has no points")
        rest = np.asarray(rest, np.float64)
        counts, indices = _topology(mesh, self.path, scene_path, key)
        faces, corner, self.poly = _triangulate(counts, indices, rest, self.path, scene_path, key)
        holes = mesh.GetHoleIndicesAttr().Get()
        self.notes = ([f"{self.path}: {len(holes)} holeIndices are not supported: those faces render solid"]
                      if holes is not None and len(holes) else [])
        self.n_points = len(rest)
        self.skinning = skinning
        if skinning is None:
            _check_unbound_skin(prim, pxr, scene_path, key)
        self.materials = _bound_materials(prim, len(counts), self.poly, scene_path, key)
        # texture coordinates only where a bound material has a texture
        self.point_of = None                 # vertex -> point, where face-varying UVs or normals split points
        self.uvs = None
        corner_uv = None
        if any(m["texture"] is not None for m in self.materials[1]):
            self.uvs, corner_uv = self._uvs(prim, faces, corner, scene_path, key)
        seams = _authored_normals(prim, corner, self.poly, pxr)
        if corner_uv is not None or seams is not None:
            faces = self._split(faces, corner_uv, seams)
        self.faces = np.ascontiguousarray(faces, np.int32)
        # visibility that changes over time (its own or an ancestor's): the
        # mesh is collapsed to a point (no triangle of it can be hit) where hidden
        self.hides = any(pxr.UsdGeom.Imageable(p).GetVisibilityAttr().ValueMightBeTimeVarying()
                         for p in _ancestors(prim) if p.IsA(pxr.UsdGeom.Imageable))
        varying = self.points_attr.ValueMightBeTimeVarying()
        placed_by = prim                     # the prim whose transform places the points
        if skinning is not None:
            anim = skinning[0].GetAnimQuery()
            placed_by = _skeleton_prim(skinning[0], prim)
            varying |= bool(anim) and (anim.JointTransformsMightBeTimeVarying()
                                       or anim.BlendShapeWeightsMightBeTimeVarying())
        moving_xform = any(UsdGeom.Xformable(p).TransformMightBeTimeVarying()
                           for p in _ancestors(placed_by) if p.IsA(UsdGeom.Xformable))
        self.static = not (varying or moving_xform or self.hides)
        self.rigid = not varying and skinning is None

    def _uvs(self, prim, faces, corner, scene_path, key):
        pxr = _pxr(scene_path, key)
        api = pxr.UsdGeom.PrimvarsAPI(prim)
        names = [m["uv_set"] for m in self.materials[1] if m["texture"] is not None]
        primvar = None
        for name in dict.fromkeys(names + ["st", "UVMap", "uv"]):
            if api.HasPrimvar(name):
                primvar = api.GetPrimvar(name)
                break
        if primvar is None:
            return None, None
        values = primvar.ComputeFlattened()
        if values is None:
            return None, None
        uv = np.asarray(values, np.float64).reshape(-1, 2)
        interp = primvar.GetInterpolation()
        if interp in ("vertex", "varying") and len(uv) == self.n_points:
            return uv.astype(np.float32), None
        if interp == "faceVarying" and len(uv) == int(corner.max(initial=-1)) + 1:
            return None, uv[corner.reshape(-1)]          # per corner: split along its seams (_split)
        if interp == "constant" or len(uv) == 1:
            return np.repeat(uv[:1], self.n_points, axis=0).astype(np.float32), None
        raise SceneError(scene_path, key, f"{self.path}: primvar {primvar.GetPrimvarName()} has "
                                          f"{interp} interpolation with {len(uv)} values; not supported")

    def _split(self, faces, corner_uv, seams):
        """Faces over vertices that split points where a corner's UV (per
        corner, face-varying) or authored normal (seams: a normal id per
        corner) differs: a vertex per distinct (point, uv, normal)."""
        if corner_uv is None and self.uvs is not None:
            corner_uv = self.uvs[faces.reshape(-1)]
        values = [v for v in (corner_uv, seams) if v is not None]
        self.point_of, kept, faces = split_at_seams(faces, *values)
        if corner_uv is not None:
            self.uvs = kept[:, :2].astype(np.float32)
        return faces

    @property
    def n_vertices(self):
        return self.n_points if self.point_of is None else len(self.point_of)

    def evaluate(self, pxr, time, xform_cache, relative_to=None):
        """World-space points (n_vertices, 3) f64 at a time code; in the
        space of the prim `relative_to` (an ancestor: a point instancer's
        prototype root) when given."""
        points = self.points_attr.Get(time)
        if self.skinning is not None:
            skel_query, skin_query = self.skinning
            if skin_query.HasBlendShapes() and skel_query.GetAnimQuery():
                weights = skel_query.GetAnimQuery().ComputeBlendShapeWeights(time)
                mapper = skin_query.GetBlendShapeMapper()
                if mapper is not None and not mapper.IsNull():
                    weights = mapper.Remap(weights)
                shapes = pxr.UsdSkel.BlendShapeQuery(pxr.UsdSkel.BindingAPI(self.prim))
                sub = shapes.ComputeSubShapeWeights(weights)
                shapes.ComputeDeformedPoints(sub[0], sub[1], sub[2], shapes.ComputeBlendShapePointIndices(),
                                             shapes.ComputeSubShapePointOffsets(), points)
            xforms = skel_query.ComputeSkinningTransforms(time)
            skin_query.ComputeSkinnedPoints(xforms, points, time)
            # skinned points are in the skeleton's space
            world = _matrix(xform_cache.GetLocalToWorldTransform(_skeleton_prim(skel_query, self.prim)))
        elif relative_to is not None:
            world = _matrix(xform_cache.ComputeRelativeTransform(self.prim, relative_to)[0])
        else:
            world = _matrix(xform_cache.GetLocalToWorldTransform(self.prim))
        pts = _apply(np.asarray(points, np.float64), world)
        if self.hides and pxr.UsdGeom.Imageable(self.prim).ComputeVisibility(time) == pxr.UsdGeom.Tokens.invisible:
            pts[:] = pts.mean(axis=0)         # hidden at this time: every triangle degenerate, never hit
        return pts if self.point_of is None else pts[self.point_of]


def _skeleton_prim(skel_query, mesh_prim):
    """The skeleton prim that places a skinned mesh's points: for a mesh
    inside an instance (an instance proxy), usd-core resolves the binding to
    the prototype's skeleton, whose transform lacks the instance's; the
    skeleton's proxy under that instance has it."""
    skel = skel_query.GetSkeleton().GetPrim()
    if not (skel.IsInPrototype() and mesh_prim.IsInstanceProxy()):
        return skel
    instance = mesh_prim
    while instance and not instance.IsPseudoRoot():
        if instance.IsInstance() and skel.GetPath().HasPrefix(instance.GetPrototype().GetPath()):
            relative = skel.GetPath().MakeRelativePath(instance.GetPrototype().GetPath())
            proxy = mesh_prim.GetStage().GetPrimAtPath(instance.GetPath().AppendPath(relative))
            return proxy if proxy else skel
        instance = instance.GetParent()
    return skel


def _check_unbound_skin(prim, pxr, scene_path, key):
    """A mesh with joint influences that UsdSkel did not bind (its skeleton
    missing, or no SkelRoot above it) would silently stay in its rest pose."""
    api = pxr.UsdSkel.BindingAPI(prim)
    if not prim.HasAPI(pxr.UsdSkel.BindingAPI) or not api.GetJointIndicesPrimvar().HasAuthoredValue():
        return
    targets = api.GetSkeletonRel().GetTargets() if api.GetSkeletonRel() else []
    target = prim.GetStage().GetPrimAtPath(targets[0]) if targets else None
    if not targets:
        problem = "has joint influences but no skel:skeleton"
    elif not target or not target.IsA(pxr.UsdSkel.Skeleton):
        problem = f"skel:skeleton targets {targets[0]}, which is not a Skeleton"
    else:
        problem = f"is bound to {targets[0]} but lies under no SkelRoot, so the binding does not resolve"
    raise SceneError(scene_path, key, f"{prim.GetPath()}: {problem}")


def _ancestors(prim):
    while prim and not prim.IsPseudoRoot():
        yield prim
        prim = prim.GetParent()


def _bound_materials(prim, n_faces, poly, scene_path, key):
    """(material slot per triangle (-1: none), [material dicts]) from the
    mesh's bound material and its materialBind GeomSubsets."""
    pxr = _pxr(scene_path, key)
    UsdShade = pxr.UsdShade
    api = UsdShade.MaterialBindingAPI(prim)
    per_face = np.full(n_faces, -1, np.int64)
    found = []

    def slot(material):
        m = material_of(material, scene_path, key) if material else None
        if m is None:
            return -1
        found.append(m)
        return len(found) - 1
    per_face[:] = slot(api.ComputeBoundMaterial()[0])
    for subset in api.GetMaterialBindSubsets():
        faces = np.asarray(subset.GetIndicesAttr().Get() or [], np.int64)
        faces = faces[(faces >= 0) & (faces < n_faces)]
        per_face[faces] = slot(UsdShade.MaterialBindingAPI(subset.GetPrim()).ComputeBoundMaterial()[0])
    if np.any(per_face < 0):
        # no material: a constant displayColor is the colour USD viewers show
        colour = pxr.UsdGeom.Gprim(prim).GetDisplayColorPrimvar().ComputeFlattened()
        if colour is not None and len(colour) == 1:
            rgb = tuple(float(min(max(c, 0.0), 1e6)) for c in colour[0])
            found.append({**DEFAULT_MATERIAL, "name": f"displayColor {rgb}", "diffuse": rgb, "uv_set": "st"})
            per_face[per_face < 0] = len(found) - 1
    return per_face[poly], found


def _input_value(shader, name):
    """(value, connected shader or None) of a shader input."""
    inp = shader.GetInput(name)
    if not inp:
        return None, None
    if inp.HasConnectedSource():
        source = inp.GetConnectedSource()
        return None, source[0]
    return inp.Get(), None


def material_of(material, scene_path, key):
    """A frustrace material from a UsdPreviewSurface: diffuseColor (value or
    UsdUVTexture, sRGB unless the texture says raw), roughness and metallic
    mapped as for glTF (anim/materials.py). None for other shaders."""
    pxr = _pxr(scene_path, key)
    shader = material.ComputeSurfaceSource()[0] if material else None
    if not shader or shader.GetIdAttr().Get() != "UsdPreviewSurface":
        return None
    colour, source = _input_value(shader, "diffuseColor")
    texture = uv_set = None
    space = "srgb"
    if source is not None:
        tex = pxr.UsdShade.Shader(source.GetPrim())
        if tex.GetIdAttr().Get() == "UsdUVTexture":
            asset, _ = _input_value(tex, "file")
            if asset is not None and asset.resolvedPath:
                texture = _texture_source(asset.resolvedPath, pxr)
            elif asset is not None and asset.path:
                raise SceneError(scene_path, key, f"{tex.GetPath()}: texture file not found: {asset.path}")
            cs, _ = _input_value(tex, "sourceColorSpace")
            space = "linear" if cs == "raw" else ("srgb" if cs == "sRGB" else "auto")
            _, reader = _input_value(tex, "st")
            if reader is not None:
                name, _ = _input_value(pxr.UsdShade.Shader(reader.GetPrim()), "varname")
                uv_set = str(name) if name else None
            scale, _ = _input_value(tex, "scale")
            colour = tuple(scale)[:3] if scale is not None else (1.0, 1.0, 1.0)
        colour = colour if colour is not None else (0.8, 0.8, 0.8)
    colour = tuple(colour) if colour is not None else (0.18, 0.18, 0.18)     # UsdPreviewSurface's default
    roughness, _ = _input_value(shader, "roughness")
    metallic, _ = _input_value(shader, "metallic")
    return pbr_material(str(material.GetPrim().GetPath()), colour, 0.5 if roughness is None else roughness,
                        0.0 if metallic is None else metallic, texture, space, uv_set or "st")


def _texture_source(resolved, pxr):
    """A texture file's path, or (bytes, suffix) for one inside a package
    (a .usdz's 'pkg.usdz[textures/a.png]'), read through USD's asset resolver."""
    if not resolved.endswith("]") or "[" not in resolved:
        return Path(resolved)
    inner = resolved[resolved.rindex("[") + 1:-1]
    asset = pxr.Ar.GetResolver().OpenAsset(pxr.Ar.ResolvedPath(resolved))
    data = asset.GetBuffer() if asset else None
    if data is None:
        return Path(resolved)                 # reading it then names the file in a clear error
    return bytes(data), Path(inner).suffix or ".png"


def _skinning_targets(stage, cache, pxr):
    """Mesh prim path -> (SkelQuery, SkinningQuery) for every skinned mesh;
    found once per stage (a whole-stage scene has an object per mesh)."""
    key = id(stage)
    if _SKINNED.get(key, (None,))[0] is stage:
        return _SKINNED[key][1]
    targets = {}
    # through instance proxies: a skinned character may be an instanceable reference
    flags = pxr.Usd.TraverseInstanceProxies(pxr.Usd.PrimDefaultPredicate)
    for prim in stage.Traverse(flags):
        if not prim.IsA(pxr.UsdSkel.Root):
            continue
        root = pxr.UsdSkel.Root(prim)
        cache.Populate(root, flags)
        for binding in cache.ComputeSkelBindings(root, flags):
            skel_query = cache.GetSkelQuery(binding.GetSkeleton())
            if not skel_query:
                continue
            for skin_query in binding.GetSkinningTargets():
                targets[str(skin_query.GetPrim().GetPath())] = (skel_query, skin_query)
    _SKINNED[key] = (stage, targets)
    return targets


def mesh_prims(stage, root, scene_path, key):
    """Every UsdGeomMesh under root (visible, not a guide or proxy), through
    instanceable prims (their instance proxies: each instance's meshes), and
    every PointInstancer (whose prototypes beneath it are its own, not
    rendered in their own right)."""
    pxr = _pxr(scene_path, key)
    UsdGeom = pxr.UsdGeom
    found = []
    it = iter(pxr.Usd.PrimRange(root, pxr.Usd.TraverseInstanceProxies(pxr.Usd.PrimDefaultPredicate)))
    for prim in it:
        if prim.IsA(UsdGeom.Imageable):
            img = UsdGeom.Imageable(prim)
            # hidden for good (not by time samples: those meshes hide per frame, _Mesh.hides)
            hidden = img.ComputeVisibility() == UsdGeom.Tokens.invisible and not any(
                UsdGeom.Imageable(p).GetVisibilityAttr().ValueMightBeTimeVarying()
                for p in _ancestors(prim) if p.IsA(UsdGeom.Imageable))
            if hidden or img.ComputePurpose() in (UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy):
                it.PruneChildren()
                continue
        if prim.IsA(UsdGeom.PointInstancer):
            found.append(prim)
            it.PruneChildren()
        elif prim.IsA(UsdGeom.Mesh):
            found.append(prim)
    return found


class UsdObject:
    """The meshes under one prim of a stage, as one frustrace object;
    `place(t, out, transform)` writes the posed vertices (n, 3) f32."""

    def __init__(self, path, prim_path, scene_path, key, instancing="flatten"):
        """instancing: how point instancers' copies are made (render.instancing)."""
        self.path, self.scene_path, self.key = Path(path), scene_path, key
        pxr = self.pxr = _pxr(scene_path, key)
        self.stage, cache = open_stage(path, scene_path, key)
        root = self.stage.GetPseudoRoot()
        if prim_path is not None:
            root = self.stage.GetPrimAtPath(prim_path) if pxr.Sdf.Path.IsValidPathString(prim_path) else None
            if not root:
                raise SceneError(scene_path, key.rsplit(".", 1)[0] + ".prim",
                                 f"{self.path.name}: no prim {prim_path}")
        prims = mesh_prims(self.stage, root, scene_path, key)
        where = prim_path or "the stage"
        if not prims:
            raise SceneError(scene_path, key, f"{self.path.name}: no mesh under {where}")
        skinned = _skinning_targets(self.stage, cache, pxr)
        self.tcps = self.stage.GetTimeCodesPerSecond() or 24.0
        def mesh_of(prim):
            return _Mesh(prim, skinned.get(str(prim.GetPath())), scene_path, key)

        def meshes_under(proto_root):
            return mesh_prims(self.stage, proto_root, scene_path, key)

        proxies = self._proxies(prims, skinned, mesh_of, instancing)
        grouped = {} if proxies is None else {str(p.GetPath()): None for p in proxies.proxies}
        self.meshes = [PointInstancer(p, pxr, meshes_under, mesh_of, scene_path, key, instancing)
                       if p.IsA(pxr.UsdGeom.PointInstancer) else mesh_of(p)
                       for p in prims if str(p.GetPath()) not in grouped]
        flat_at = self._flattened_places(prims, proxies)
        if proxies is not None:
            self.meshes.append(proxies)
        self.notes = [note for m in self.meshes for note in m.notes]
        # meshes that ask for a subdivision surface: rendered as their cage (the scene warns once)
        # a point instancer's meshes are its blocks' prototype meshes
        meshes = _plain_meshes(self.meshes)
        self.subdivided = [m.path for m in meshes
                           if pxr.UsdGeom.Mesh(m.prim).GetSubdivisionSchemeAttr().Get() != pxr.UsdGeom.Tokens.none]
        offsets = np.cumsum([0] + [m.n_vertices for m in self.meshes])
        self.offsets = offsets
        self.faces = np.ascontiguousarray(np.concatenate([m.faces + o for m, o in zip(self.meshes, offsets)]),
                                          np.int32)
        self.uvs = np.concatenate([m.uvs if m.uvs is not None else np.zeros((m.n_vertices, 2), np.float32)
                                   for m in self.meshes]).astype(np.float32)
        # materials: a slot per distinct material, per triangle
        self.materials, slots, face_material = {}, {}, []
        # two-level point instancers and instance proxies: segments (first face, end, copies, where
        # the flattened world numbers them: 0 copies, placed as they are), each block's copies'
        # material slots (or None), the faces those replace
        self.segments, self.instance_slots, self.block_static, plain, face0 = [], [], [], [], 0
        for m in self.meshes:
            per_tri, found = m.materials
            local = np.full(len(found) + 1, -1, np.int32)
            for j, mat in enumerate(found):
                local[j] = slots.setdefault(mat["name"], len(slots))
                self.materials[local[j]] = mat
            face_material.append(local[per_tri])
            if getattr(m, "two_level", False):
                for (lo, hi), (proto, _, ids, _), copy_slots, at in zip(m.block_faces, m.blocks, m.block_slots,
                                                                          flat_at[id(m)]):
                    self.segments.append((face0 + lo, face0 + hi, len(ids), at))
                    self.instance_slots.append(None if copy_slots is None else local[copy_slots])
                    self.block_static.append(proto.static)
                plain.append(m.plain)
            else:
                self.segments.append((face0, face0 + len(m.faces), 0, flat_at[id(m)]))
                plain.append(np.zeros(len(m.faces), bool))
            face0 += len(m.faces)
        self.face_material = np.concatenate(face_material)
        self.plain = np.concatenate(plain)
        self.two_level = any(copies for _, _, copies, _ in self.segments)
        self.static = all(m.static for m in self.meshes)
        self.rigid = all(m.rigid for m in self.meshes)     # moved by transforms only
        self.rest = self._evaluate(0.0, every=True)

    def _proxies(self, prims, skinned, mesh_of, instancing):
        """The instance proxies among prims as one two-level ProxyInstances
        (anim/io/usd_proxies.py) when render.instancing chooses it for their
        copied triangles, else None."""
        if instancing == "flatten":
            return None
        groups = proxy_groups(prims, self.pxr, skinned)
        if not groups:
            return None
        proxies = ProxyInstances(list(groups.values()), mesh_of, self.pxr, self.scene_path, self.key)
        copied = sum(len(roots) * (hi - lo) for roots, (lo, hi) in zip(proxies.roots, proxies.block_faces))
        return proxies if two_level(instancing, copied, len(proxies.proxies)) else None

    def _flattened_places(self, prims, proxies):
        """{id(mesh): where the flattened world numbers its triangles}: a
        mesh's first triangle ([start]), a two-level point instancer's
        blocks' copies' (a list of arrays, block by block, as it lays them
        out), the instance proxies' copies' (in the stage's order)."""
        copy_of = {} if proxies is None else {str(prim.GetPath()): (b, c) for b, group in enumerate(proxies.groups)
                                              for c, prim in enumerate(group)}
        by_path = {m.path: m for m in self.meshes}
        out = {} if proxies is None else {id(proxies): [np.empty(len(r), np.int64) for r in proxies.roots]}
        start = 0
        for prim in prims:
            path = str(prim.GetPath())
            if path in copy_of:
                b, c = copy_of[path]
                out[id(proxies)][b][c] = start
                lo, hi = proxies.block_faces[b]
                start += hi - lo
                continue
            m = by_path[path]
            if getattr(m, "two_level", False):
                out[id(m)] = []
                for (lo, hi), (_, _, ids, _) in zip(m.block_faces, m.blocks):
                    out[id(m)].append(start + np.arange(len(ids), dtype=np.int64) * (hi - lo))
                    start += len(ids) * (hi - lo)
            else:
                out[id(m)] = np.array([start], np.int64)
                start += len(m.faces)
        return out

    def time_range(self):
        """(t0, t1) in seconds of the stage's authored time code range, or None."""
        if not self.stage.HasAuthoredTimeCodeRange():
            return None
        return self.stage.GetStartTimeCode() / self.tcps, self.stage.GetEndTimeCode() / self.tcps

    def time_code(self, t):
        return self.pxr.Usd.TimeCode(t * self.tcps)

    def _evaluate(self, t, every):
        time = self.time_code(t)
        cache = self.pxr.UsdGeom.XformCache(time)
        out = np.empty((self.offsets[-1], 3), np.float64)
        for m, o in zip(self.meshes, self.offsets):
            if every or not m.static:
                out[o:o + m.n_vertices] = m.evaluate(self.pxr, time, cache)
        return out

    def place(self, t, out, transform=None):
        """Posed vertices at scene time t into out (n, 3) f32; `transform` (3, 4) on top
        (not on a two-level instancer's prototypes: instance_matrices carries it)."""
        pts = self._evaluate(t, every=False)
        for m, o in zip(self.meshes, self.offsets):
            if m.static:
                pts[o:o + m.n_vertices] = self.rest[o:o + m.n_vertices]
        if transform is not None:
            moved = pts @ np.asarray(transform)[:, :3].T + np.asarray(transform)[:, 3]
            for m, o in zip(self.meshes, self.offsets):
                if getattr(m, "two_level", False):
                    moved[o:o + m.n_vertices] = pts[o:o + m.n_vertices]
            pts = moved
        if not np.all(np.isfinite(pts)):
            raise SceneError(self.scene_path, self.key, f"{self.path.name}: non-finite points at t = {t:g}")
        out[...] = pts


    def instance_matrices(self, t, transform=None):
        """Per two-level block (self.segments with copies), its copies'
        (n_b, 3, 4) world-from-prototype matrices at scene time t, with
        `transform` (3, 4) on top."""
        time = self.time_code(t)
        cache = self.pxr.UsdGeom.XformCache(time)
        out = [b for m in self.meshes if getattr(m, "two_level", False)
               for b in m.instance_matrices(self.pxr, time, cache)]    # in self.segments' order
        if transform is not None:
            top = np.asarray(transform, np.float64)
            for b in out:
                b[:, :, 3] = b[:, :, 3] @ top[:, :3].T + top[:, 3]
                b[:, :, :3] = np.einsum("ij,njk->nik", top[:, :3], b[:, :, :3])
        for b in out:
            if not np.all(np.isfinite(b)):
                raise SceneError(self.scene_path, self.key, f"{self.path.name}: an instance transform is inf or "
                                                            f"NaN at t = {t:g}")
        return out


def _plain_meshes(meshes):
    """The meshes among `meshes` and inside their point instancers' (and
    those instancers' nested instancers') prototypes."""
    out = []
    for m in meshes:
        if hasattr(m, "blocks"):
            out += _plain_meshes([b[0] for b in m.blocks])
        else:
            out.append(m)
    return out


def _lights(stage, time, pxr, notes):
    """frustrace light dicts from UsdLux lights (as at `time`)."""
    UsdLux, UsdGeom = pxr.UsdLux, pxr.UsdGeom
    cache = UsdGeom.XformCache(time)
    lights = []
    for prim in stage.Traverse():
        kind = ("sphere" if prim.IsA(UsdLux.SphereLight) else "rect" if prim.IsA(UsdLux.RectLight)
                else "distant" if prim.IsA(UsdLux.DistantLight) else None)
        if kind is None:
            if prim.HasAPI(UsdLux.LightAPI):
                notes.append(f"light {prim.GetPath()} ({prim.GetTypeName()}) is not supported; left out")
            continue
        api = UsdLux.LightAPI(prim)
        m = _matrix(cache.GetLocalToWorldTransform(prim))
        power = float(api.GetIntensityAttr().Get(time) or 0.0) * 2.0 ** float(api.GetExposureAttr().Get(time) or 0.0)
        colour = tuple(float(c) for c in (api.GetColorAttr().Get(time) or (1.0, 1.0, 1.0)))
        normalize = bool(api.GetNormalizeAttr().Get(time))
        origin = m[3, :3]
        if kind == "distant":
            d = -m[2, :3]
            lights.append({"type": "directional", "direction": _vec(d / np.linalg.norm(d)),
                           "color": colour, "intensity": power})
        elif kind == "sphere":
            light = UsdLux.SphereLight(prim)
            r = float(light.GetRadiusAttr().Get(time) or 0.0) * float(np.linalg.norm(m[0, :3]))
            area = math.pi * r * r if (r > 0 and not normalize) else 1.0
            lights.append({"type": "point", "position": _vec(origin), "color": colour, "intensity": power * area})
        else:
            light = UsdLux.RectLight(prim)
            w = float(light.GetWidthAttr().Get(time) or 1.0)
            h = float(light.GetHeightAttr().Get(time) or 1.0)
            eu, ev = m[0, :3] * w, m[1, :3] * h
            area = 1.0 if normalize else float(np.linalg.norm(np.cross(eu, ev)))
            # it emits along its -Z only: edges ordered so that edge_u x edge_v = -Z (sides: 1)
            lights.append({"type": "area", "corner": _vec(origin - 0.5 * eu - 0.5 * ev), "edge_u": _vec(ev),
                           "edge_v": _vec(eu), "sides": 1, "color": colour, "intensity": power * area})
    return lights


def _vec(v):
    return [float(x) for x in v]


def _camera_prim(stage, camera, pxr, scene_path):
    if camera is not None:
        prim = stage.GetPrimAtPath(camera) if pxr.Sdf.Path.IsValidPathString(camera) else None
        if not prim or not prim.IsA(pxr.UsdGeom.Camera):
            raise SceneError(scene_path, "--camera", f"no camera {camera} in the stage")
        return prim
    for prim in stage.Traverse():
        if prim.IsA(pxr.UsdGeom.Camera):
            return prim
    return None


def _camera_at(prim, time, pxr):
    """(eye, look_at, up, vertical fov in degrees, aspect) of a UsdGeomCamera."""
    cam = pxr.UsdGeom.Camera(prim).GetCamera(time)
    m = _matrix(cam.transform)
    eye = m[3, :3]
    forward = -m[2, :3] / np.linalg.norm(m[2, :3])
    up = m[1, :3] / np.linalg.norm(m[1, :3])
    fov = math.degrees(2 * math.atan(cam.verticalAperture / (2 * cam.focalLength)))
    return eye, eye + forward, up, min(max(fov, 1e-3), 179.0), cam.horizontalAperture / cam.verticalAperture


def _lens_and_shutter(prim, time, pxr, notes) -> tuple:
    """({aperture_radius, focus_distance} or {}, {shutter, position} or {})
    of a UsdGeomCamera. The lens: fStop > 0 gives a thin lens of diameter
    focalLength / fStop (focalLength is in tenths of a scene unit, as the
    apertures), focused at focusDistance (scene units); both at the first
    frame. The shutter: shutter:open and shutter:close are offsets from the
    frame time in frames, which render.motion_blur takes when the shutter
    opens at it, closes at it, or is centred on it."""
    usd_cam = pxr.UsdGeom.Camera(prim)
    cam = usd_cam.GetCamera(time)
    lens, blur = {}, {}
    if cam.fStop > 0 and cam.focusDistance > 0:
        radius = cam.focalLength * pxr.Gf.Camera.FOCAL_LENGTH_UNIT / (2 * cam.fStop)
        lens = {"aperture_radius": radius, "focus_distance": float(cam.focusDistance)}
        notes.append(f"depth of field from the camera: f/{cam.fStop:g}, focal length {cam.focalLength:g}, "
                     f"focused at {cam.focusDistance:g}: lens radius {radius:.4g} (seen with spp > 1)")
    elif cam.fStop > 0:
        notes.append(f"the camera's fStop {cam.fStop:g} has no focusDistance: rendered as a pinhole")
    open_, close = usd_cam.GetShutterOpenAttr().Get(time), usd_cam.GetShutterCloseAttr().Get(time)
    if open_ is not None and close is not None and close > open_:
        position = ("start" if open_ == 0 else "end" if close == 0 else
                    "center" if math.isclose(open_, -close) else None)
        if position is None:
            notes.append(f"shutter {open_:g}..{close:g} frames is not opened, closed or centred at the frame "
                         "time: taken as centred")
            position = "center"
        blur = {"shutter": float(close - open_), "position": position}
        notes.append(f"motion blur from the camera: shutter {open_:g}..{close:g} frames ({position}; seen with "
                     "spp > 1)")
    return lens, blur


def _instances_subtree(stage, prims, skel_cache, pxr, instancing):
    """The path of the nearest prim holding every instance whose proxies
    are traced two-level, or None (none are: flattened)."""
    if instancing == "flatten":
        return None
    groups = proxy_groups(prims, pxr, _skinning_targets(stage, skel_cache, pxr))
    copied = sum(len(g) * sum(max(c - 2, 0) for c in (pxr.UsdGeom.Mesh(g[0]).GetFaceVertexCountsAttr().Get() or []))
                 for g in groups.values())
    if not groups or not two_level(instancing, copied, sum(len(g) for g in groups.values())):
        return None
    roots = [instance_root(p).GetPath() for g in groups.values() for p in g]
    common = roots[0]
    for r in roots[1:]:
        common = common.GetCommonPrefix(r)
    return common


def scene_of_stage(path, camera=None, instancing="auto"):
    """A scene file's data (anim/schema.py) for a whole USD stage, and notes
    on what came from the stage and what from frustrace's defaults.
    Every mesh is an object of its own, but where instance proxies are
    traced two-level (render.instancing) the subtree that holds their
    instances is one object, so that they can share their prototypes."""
    path = Path(path)
    pxr = _pxr(path, "")
    stage, skel_cache = open_stage(path, path, "")
    notes = [f"USD stage: upAxis {pxr.UsdGeom.GetStageUpAxis(stage)}, metersPerUnit "
             f"{pxr.UsdGeom.GetStageMetersPerUnit(stage):g} (as authored: no conversion)"]
    fps = stage.GetFramesPerSecond() or 24.0
    tcps = stage.GetTimeCodesPerSecond() or 24.0
    if stage.HasAuthoredTimeCodeRange():
        start = math.ceil(stage.GetStartTimeCode() / tcps * fps - 1e-9)
        end = max(start, math.floor(stage.GetEndTimeCode() / tcps * fps + 1e-9))
        notes.append(f"frames {start}..{end} at {fps:g} fps from the stage's time codes "
                     f"({stage.GetStartTimeCode():g}..{stage.GetEndTimeCode():g}, {tcps:g} per second)")
    else:
        start = end = 0
        notes.append("the stage has no time code range: frame 0 only (frustrace's default)")
    prims = mesh_prims(stage, stage.GetPseudoRoot(), path, "")
    if not prims:
        raise SceneError(path, "", "no mesh in the stage")
    shared = _instances_subtree(stage, prims, skel_cache, pxr, instancing)
    objects = []
    for p in prims:
        where = shared if shared is not None and p.GetPath().HasPrefix(shared) else p.GetPath()
        if not objects or objects[-1]["prim"] != str(where):
            objects.append({"name": str(where), "mesh": path.name, "prim": str(where)})
    if shared is not None:
        notes.append(f"instance proxies under {shared} traced two-level (render.instancing)")
    time0 = pxr.Usd.TimeCode(start / fps * tcps)
    cam_prim = _camera_prim(stage, camera, pxr, path)
    width = 512
    if cam_prim is not None and pxr.UsdGeom.Camera(cam_prim).GetProjectionAttr().Get() == "orthographic":
        raise SceneError(path, "--camera" if camera else "", f"camera {cam_prim.GetPath()} is orthographic; "
                                                             "frustrace renders perspective cameras only")
    if cam_prim is not None:
        keys = []
        for f in range(start, end + 1):
            eye, look, up, fov, aspect = _camera_at(cam_prim, pxr.Usd.TimeCode(f / fps * tcps), pxr)
            keys.append({"t": f / fps, "eye": _vec(eye), "look_at": _vec(look), "up": _vec(up), "fov": fov})
        height = max(1, round(width / aspect))
        notes.append(f"resolution {width}x{height}: frustrace's default width, the camera's aperture aspect "
                     "(render --res to change it)")
        still = all({k: v for k, v in key.items() if k != "t"} == {k: v for k, v in keys[0].items() if k != "t"}
                    for key in keys)
        cam = ({k: keys[0][k] for k in ("eye", "look_at", "up", "fov")} if still
               else {"keys": keys, "interpolation": "linear"})
        notes.append(f"camera {cam_prim.GetPath()} (vertical field of view {keys[0]['fov']:.2f} degrees)")
        lens, blur = _lens_and_shutter(cam_prim, time0, pxr, notes)
        cam.update(lens)
    else:
        blur = {}
        cam, height = _default_camera(stage, time0, pxr), width
        notes.append("no camera in the stage: frustrace's default view of the bounds at the first frame")
    lights = _lights(stage, time0, pxr, notes)
    if lights:
        notes.append(f"{len(lights)} light(s) from UsdLux")
    else:
        # as USD viewers do (usdview's camera light): a light at the eye, of
        # the intensity that lights the centre of the bounds with irradiance 1
        eye = np.array(cam["eye"] if "eye" in cam else cam["keys"][0]["eye"])
        lo, hi = _bounds(stage, time0, pxr)
        d2 = float(np.sum(((lo + hi) / 2 - eye) ** 2)) or 1.0
        lights = [{"type": "point", "position": _vec(eye), "intensity": d2}]
        notes.append("no lights in the stage: a point light at the camera, as USD viewers do")
    data = {"version": 1, "frames": {"start": start, "end": end, "fps": float(fps)},
            "output": {"resolution": [width, height]}, "camera": cam, "lights": lights, "objects": objects,
            **({"render": {"motion_blur": blur}} if blur else {})}
    return data, notes


def _bounds(stage, time, pxr):
    """(lo, hi) of the stage's renderable bounds at a time code."""
    bbox = pxr.UsdGeom.BBoxCache(time, [pxr.UsdGeom.Tokens.default_, pxr.UsdGeom.Tokens.render])
    box = bbox.ComputeWorldBound(stage.GetPseudoRoot()).ComputeAlignedRange()
    lo, hi = np.array(box.GetMin()), np.array(box.GetMax())
    if box.IsEmpty() or not np.all(np.isfinite(lo)):
        lo, hi = -np.ones(3), np.ones(3)
    return lo, hi


def _default_camera(stage, time, pxr):
    """A view of the stage's bounds from the front (along -Y for Z-up, -Z for Y-up)."""
    lo, hi = _bounds(stage, time, pxr)
    centre, size = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) or 1.0
    z_up = pxr.UsdGeom.GetStageUpAxis(stage) == pxr.UsdGeom.Tokens.z
    back = np.array([0, -1, 0]) if z_up else np.array([0, 0, 1])
    up = [0.0, 0.0, 1.0] if z_up else [0.0, 1.0, 0.0]
    return {"eye": _vec(centre + 1.6 * size * back), "look_at": _vec(centre), "up": up, "fov": 40.0}


def dependencies(path) -> list:
    """Every file a stage needs (its layers and assets: textures), for the
    cluster's bundle; absolute paths."""
    from pxr import UsdUtils
    layers, assets, _ = UsdUtils.ComputeAllDependencies(str(path))
    # a file inside a .usdz ('pkg.usdz[a.png]') travels with its package
    files = [layer.realPath for layer in layers if layer.realPath] + [str(a) for a in assets]
    return list(dict.fromkeys(Path(f.split("[", 1)[0]) for f in files))
