"""USD PointInstancers as one block of vertices: every prototype mesh,
copied once per instance that uses its prototype, placed as usd-core
places it (`ComputeInstanceTransformsAtTime`: positions, orientations,
scales, the prototype root's own transform as the most local part, and its
interpolation between time samples), then by the instancer's own
transform; instances masked by invisibleIds or inactiveIds
(`ComputeMaskAtTime`) collapse to a point, so none of their triangles can
be hit.

The copies are made into the frame's triangles (as glTF's shared meshes
are): memory and build time grow with instances x prototype size. Or,
two-level (render.instancing), each prototype mesh is read once, in the
space of its prototype root, and `instance_matrices` places its copies
(raycore/instancing traces them), each with its displayColor as its own
material.

usd.py hands in how it reads a mesh (`mesh_of`) and finds the meshes under
a prim (`meshes_under`), so that this module does not import it back."""
import numpy as np

from anim.errors import SceneError
from anim.instances import two_level
from anim.materials import DEFAULT_MATERIAL
from anim.memory import check_copies

_INSTANCE_ATTRS = ("protoIndices", "positions", "orientations", "orientationsf", "scales", "invisibleIds",
                   "inactiveIds", "velocities", "angularVelocities", "accelerations")


def _matrix(m):
    return np.array(m, np.float64).reshape(-1, 4, 4)


class PointInstancer:
    """One UsdGeomPointInstancer, read as a mesh is by UsdObject: faces,
    uvs, materials, static, rigid, notes, n_vertices and evaluate()."""

    def __init__(self, prim, pxr, meshes_under, mesh_of, scene_path, key, instancing="flatten"):
        """instancing: render.instancing's choice (auto: as
        anim.instances.two_level measured it)."""
        self.prim, self.path = prim, str(prim.GetPath())
        self.scene_path, self.key = scene_path, key
        schema = self.schema = pxr.UsdGeom.PointInstancer(prim)
        self.notes = []
        stage = prim.GetStage()
        targets = schema.GetPrototypesRel().GetTargets()
        if not targets:
            self._fail("has no prototypes")
        roots = []
        for target in targets:
            root = stage.GetPrimAtPath(target)
            if not root:
                self._fail(f"prototype {target} does not exist")
            if self.path == str(target) or self.path.startswith(str(target) + "/"):
                self._fail(f"prototype {target} holds the instancer itself: a cycle of prototypes")
            roots.append(root)
        self.proto = self._proto_indices(len(roots))
        n = len(self.proto)
        self._check_arrays(n)
        colours = self._instance_colours(pxr, n)
        self.blocks = []          # (mesh, prototype root, instance ids, vertex offset)
        parts = []                # (prototype root, its instances, its meshes)
        for p, root in enumerate(roots):
            ids = np.flatnonzero(self.proto == p)
            if len(ids) == 0:
                continue
            prims = meshes_under(root)
            if not prims:
                self._fail(f"prototype {root.GetPath()} has no mesh")
            # a point instancer inside a prototype: its copies, made into triangles, are part of the prototype
            parts.append((root, ids, [PointInstancer(m, pxr, meshes_under, mesh_of, scene_path, key, "flatten")
                                      if m.IsA(pxr.UsdGeom.PointInstancer) else mesh_of(m) for m in prims]))
        copied = sum(len(ids) * len(m.faces) for _, ids, meshes in parts for m in meshes)
        self.two_level = two_level(instancing, copied, n)
        if not self.two_level:
            check_copies(copied, f"point instancer {self.path}: {n:,} instances", scene_path, key)
        faces, uvs, per_tri, found, offset = [], [], [], [], 0
        # two-level: each block's faces in self.faces, its copies' material slots (or None) and the
        # prototype triangles those replace (no material of their own)
        self.block_faces, self.block_slots, plain_tris = [], [], []
        for root, ids, meshes in parts:
            for mesh in meshes:
                if mesh.skinning is not None:
                    self._fail(f"prototype mesh {mesh.path} is skinned; skinned prototypes are not supported")
                nv = mesh.n_vertices
                copies = 1 if self.two_level else len(ids)
                self.blocks.append((mesh, root, ids, offset))
                face0 = sum(len(f) for f in faces)
                faces.append((mesh.faces[None] + (offset + np.arange(copies) * nv)[:, None, None]).reshape(-1, 3))
                self.block_faces.append((face0, face0 + len(mesh.faces)))
                if mesh.uvs is not None:
                    uvs.append((offset, np.tile(mesh.uvs, (copies, 1))))
                tri, mats = mesh.materials
                slots = np.tile(material_slots(tri, mats, found)[None], (copies, 1))
                plain = np.zeros(len(tri), bool)
                slot_of_copy = None
                if colours is not None:
                    # the instancer's displayColor, per copy, where the prototype has no material of its own
                    plain = (tri < 0) | np.array([mats[k]["name"].startswith("displayColor") if k >= 0 else True
                                                  for k in tri], bool)
                    slot_of_copy = colour_slot(colours, ids, found)
                    if not self.two_level:
                        slots[:, plain] = slot_of_copy[:, None]
                self.block_slots.append(slot_of_copy)
                plain_tris.append(plain)
                per_tri.append(slots.reshape(-1))
                self.notes += mesh.notes
                offset += nv * copies
        self.plain = np.concatenate(plain_tris)
        self.n_vertices = offset
        if offset >= 2 ** 31:
            self._fail(f"{n} instances make {offset} vertices, more than 2^31")
        self.faces = np.ascontiguousarray(np.concatenate(faces), np.int32)
        self.uvs = joined_uvs(uvs, offset)
        self.materials = (np.concatenate(per_tri).astype(np.int64), found)
        self.skinning = None
        self.hides = any(pxr.UsdGeom.Imageable(p).GetVisibilityAttr().ValueMightBeTimeVarying()
                         for p in _ancestors(prim))
        moving_xform = any(pxr.UsdGeom.Xformable(p).TransformMightBeTimeVarying()
                           for p in _ancestors(prim) if p.IsA(pxr.UsdGeom.Xformable))
        varying = any(prim.GetAttribute(a).ValueMightBeTimeVarying() for a in _INSTANCE_ATTRS
                      if prim.GetAttribute(a))
        self.static = not (moving_xform or varying or self.hides) and all(b[0].static for b in self.blocks)
        self.rigid = False
        self.n_instances = n

    def _instance_colours(self, pxr, n):
        """(n, 3) colours from the instancer's primvars:displayColor, one per
        instance (vertex or varying interpolation) or one for all
        (constant), or None; copies take them where their prototype has no
        material bound (as USD viewers show instance primvars)."""
        primvar = pxr.UsdGeom.PrimvarsAPI(self.prim).GetPrimvar("displayColor")
        if not primvar or not primvar.HasAuthoredValue():
            return None
        values = primvar.ComputeFlattened()
        if values is None or len(values) == 0:
            return None
        rgb = np.clip(np.asarray(values, np.float64).reshape(-1, 3), 0.0, 1e6)
        if primvar.GetInterpolation() == "constant" or len(rgb) == 1:
            return np.repeat(rgb[:1], n, axis=0)
        if len(rgb) != n:
            self._fail(f"primvars:displayColor has {len(rgb)} values for {n} instances")
        if not np.all(np.isfinite(rgb)):
            self._fail("primvars:displayColor holds inf or NaN")
        return rgb

    def _fail(self, problem):
        raise SceneError(self.scene_path, self.key, f"point instancer {self.path}: {problem}")

    def _proto_indices(self, n_protos):
        """protoIndices, the same at every time sample (instances that change
        in number or prototype over time are refused)."""
        attr = self.schema.GetProtoIndicesAttr()
        first = attr.Get(self.prim.GetStage().GetStartTimeCode()) if attr.GetNumTimeSamples() else attr.Get()
        if first is None or len(first) == 0:
            self._fail("has no protoIndices (no instances)")
        first = np.asarray(first, np.int64)
        for t in attr.GetTimeSamples():
            other = np.asarray(attr.Get(t), np.int64)
            if other.shape != first.shape or np.any(other != first):
                self._fail(f"protoIndices change at time code {t:g} ({len(first)} -> {len(other)} instances or "
                           "another prototype); instances that change over time are not supported")
        bad = np.flatnonzero((first < 0) | (first >= n_protos))
        if len(bad):
            self._fail(f"protoIndices[{bad[0]}] = {first[bad[0]]}: no such prototype (it has {n_protos})")
        return first

    def _check_arrays(self, n):
        """positions, orientations and scales: n rows at every sample, finite."""
        for name in ("positions", "orientations", "orientationsf", "scales"):
            attr = self.prim.GetAttribute(name)
            if not attr or not attr.HasAuthoredValue():
                continue
            samples = attr.GetTimeSamples() or [None]
            for t in samples:
                value = attr.Get() if t is None else attr.Get(t)
                if value is None:
                    continue
                a = np.array([[q.GetReal(), *q.GetImaginary()] for q in value] if name.startswith("orient")
                             else value, np.float64).reshape(len(value), -1)
                when = "" if t is None else f" at time code {t:g}"
                if len(a) != n:
                    self._fail(f"{name} has {len(a)} entries{when}, protoIndices {n}")
                if not np.all(np.isfinite(a)):
                    self._fail(f"{name}[{int(np.argwhere(~np.isfinite(a))[0, 0])}] is inf or NaN{when}")
        if not self.prim.GetAttribute("positions") or not self.prim.GetAttribute("positions").HasAuthoredValue():
            self._fail("has no positions")

    def _placement(self, pxr, time, xform_cache, relative_to=None):
        """(world (n, 4, 4) row-vector matrices of the instances, shown (n,) bool) at a time code;
        in the space of the prim `relative_to` (an enclosing instancer's prototype root) when given."""
        PI = pxr.UsdGeom.PointInstancer
        xf = _matrix(self.schema.ComputeInstanceTransformsAtTime(time, time, PI.IncludeProtoXform, PI.IgnoreMask))
        if len(xf) != self.n_instances:
            self._fail(f"usd-core computed {len(xf)} instance transforms at time code {time.GetValue():g}, "
                       f"not {self.n_instances}: check positions, orientations and scales")
        place = (xform_cache.GetLocalToWorldTransform(self.prim) if relative_to is None
                 else xform_cache.ComputeRelativeTransform(self.prim, relative_to)[0])
        world = xf @ _matrix(place)[0]
        if not np.all(np.isfinite(world)):
            self._fail(f"an instance transform is inf or NaN at time code {time.GetValue():g}")
        mask = self.schema.ComputeMaskAtTime(time)
        shown = np.ones(self.n_instances, bool) if len(mask) == 0 else np.asarray(mask, bool)
        if self.hides and pxr.UsdGeom.Imageable(self.prim).ComputeVisibility(time) == pxr.UsdGeom.Tokens.invisible:
            shown[:] = False
        return world, shown

    def instance_matrices(self, pxr, time, xform_cache):
        """Two-level: per block, its copies' (n_b, 3, 4) world-from-prototype
        matrices (a hidden copy's 3x3 zero)."""
        world, shown = self._placement(pxr, time, xform_cache)
        out = []
        for _, _, ids, _ in self.blocks:
            m = np.empty((len(ids), 3, 4))
            m[:, :, :3] = np.transpose(world[ids, :3, :3], (0, 2, 1)) * shown[ids, None, None]
            m[:, :, 3] = world[ids, 3, :3]
            out.append(m)
        return out

    def evaluate(self, pxr, time, xform_cache, relative_to=None):
        """World-space points (n_vertices, 3) f64 at a time code (in the
        space of `relative_to` when given, as a mesh's); two-level: each
        block's prototype mesh once, in its prototype root's space."""
        if self.two_level:
            return np.concatenate([mesh.evaluate(pxr, time, xform_cache, relative_to=root)
                                   for mesh, root, _, _ in self.blocks])
        world, shown = self._placement(pxr, time, xform_cache, relative_to)
        out = np.empty((self.n_vertices, 3), np.float64)
        for mesh, root, ids, offset in self.blocks:
            local = mesh.evaluate(pxr, time, xform_cache, relative_to=root)
            m = world[ids]
            pts = np.einsum("vj,kji->kvi", local, m[:, :3, :3]) + m[:, None, 3, :3]
            hidden = ~shown[ids]
            pts[hidden] = m[hidden, None, 3, :3]             # a hidden copy collapses to its position
            out[offset:offset + pts.shape[0] * pts.shape[1]] = pts.reshape(-1, 3)
        return out


def check_cycles(stage, pxr, scene_path, key):
    """SceneError naming a cycle of point instancers (a prototype that holds
    its own instancer, directly or through other instancers' prototypes),
    before anything in usd-core recurses through it (its bounds computation
    overflows the stack on one)."""
    flags = pxr.Usd.TraverseInstanceProxies(pxr.Usd.PrimDefaultPredicate)
    instancers = {str(p.GetPath()): p for p in stage.Traverse(flags) if p.IsA(pxr.UsdGeom.PointInstancer)}
    edges = {}
    for path, prim in instancers.items():
        targets = [str(t) for t in pxr.UsdGeom.PointInstancer(prim).GetPrototypesRel().GetTargets()]
        edges[path] = [(t, other) for t in targets for other in instancers
                       if other == t or other.startswith(t.rstrip("/") + "/")]
    state = {}

    def visit(path, trail):
        state[path] = "open"
        for target, other in edges[path]:
            if state.get(other) == "open":
                loop = trail[trail.index(other):] + [other] if other in trail else [path, other]
                raise SceneError(scene_path, key, f"point instancer {path}: prototype {target} holds "
                                                  f"{'the instancer itself' if other == path else other}: a cycle "
                                                  f"of prototypes ({' -> '.join(loop)})")
            if other not in state:
                visit(other, trail + [other])
        state[path] = "done"

    for path in instancers:
        if path not in state:
            visit(path, [path])


def material_slots(tri, mats, found):
    """A mesh's triangles' material slots (tri: into its materials mats,
    -1 none) as slots of `found`, to which mats are appended."""
    local = np.arange(len(mats) + 1) + len(found)
    local[-1] = -1
    found += mats
    return np.where(tri >= 0, local[tri], -1)


def joined_uvs(uvs, n):
    """(n, 2) f32 UVs from (first vertex, uvs) blocks (zeros elsewhere), or
    None when there are none."""
    if not uvs:
        return None
    out = np.zeros((n, 2), np.float32)
    for first, u in uvs:
        out[first:first + len(u)] = u
    return out


def colour_slot(colours, ids, found):
    """The material slot of each copy's colour (colours[ids]), appending a
    displayColor material per distinct colour to `found`."""
    unique, inverse = np.unique(colours[ids], axis=0, return_inverse=True)
    base = len(found)
    for rgb in unique:
        rgb = tuple(float(c) for c in rgb)
        found.append({**DEFAULT_MATERIAL, "name": f"displayColor {rgb}", "diffuse": rgb, "uv_set": "st"})
    return base + inverse.reshape(-1)


def _ancestors(prim):
    while prim and not prim.IsPseudoRoot():
        yield prim
        prim = prim.GetParent()
