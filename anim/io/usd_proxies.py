"""USD instanceable prims traced two-level: the meshes that instance
proxies show, grouped by the prototype mesh they stand for (and the
material bound to them, which an instance may override above its
prototype), each group's mesh read once in its instance root's space and
placed by every instance root's world transform (raycore/instancing).

Flattened, each proxy is a mesh of its own (usd.mesh_prims); this module
takes those that can share: not skinned, not hidden at some times, not
inside a prototype that is itself instanced within another prototype.
The copies keep their place in the flattened numbering (`flat_at`), so
that the `id` AOV is the same either way.
"""
import numpy as np

from anim.errors import SceneError
from anim.io.usd_instancer import joined_uvs, material_slots


def instance_root(prim):
    """The nearest ancestor of an instance proxy that is an instance."""
    while prim and not prim.IsInstance():
        prim = prim.GetParent()
    return prim


def binding_key(prim, pxr):
    """The materials bound to a proxy and its subsets (paths): copies that
    differ there are not one group."""
    api = pxr.UsdShade.MaterialBindingAPI(prim)
    paths = [str(api.ComputeBoundMaterial()[0].GetPath())]
    for subset in api.GetMaterialBindSubsets():
        paths.append(str(pxr.UsdShade.MaterialBindingAPI(subset.GetPrim()).ComputeBoundMaterial()[0].GetPath()))
    return tuple(paths)


def proxy_groups(prims, pxr, skinned):
    """{(prototype mesh path, materials): [proxy prims]} of the proxies in
    prims that can share a prototype's mesh."""
    groups = {}
    for prim in prims:
        if not prim.IsInstanceProxy() or not prim.IsA(pxr.UsdGeom.Mesh) or str(prim.GetPath()) in skinned:
            continue
        proto = prim.GetPrimInPrototype()
        root = instance_root(prim)
        if not proto or not root or proto.IsInstanceProxy() or instance_root(root.GetParent()):
            continue                              # nested instancing: flattened
        if any(pxr.UsdGeom.Imageable(p).GetVisibilityAttr().ValueMightBeTimeVarying()
               for p in _ancestors(prim) if p.IsA(pxr.UsdGeom.Imageable)):
            continue                              # hidden at some times: flattened
        groups.setdefault((str(proto.GetPath()), binding_key(prim, pxr)), []).append(prim)
    return {k: v for k, v in groups.items() if len(v) > 1}


def _ancestors(prim):
    while prim and not prim.IsPseudoRoot():
        yield prim
        prim = prim.GetParent()


def _matrix(m):
    return np.array(m, np.float64).reshape(-1, 4, 4)


class ProxyInstances:
    """Groups of instance proxies as one two-level mesh-like object (the
    interface usd.UsdObject reads from a mesh, and from a two-level point
    instancer): each group's mesh once (faces, uvs, materials), evaluate()
    its points in its instance root's space, instance_matrices() each
    copy's instance root in the world."""
    two_level = True

    def __init__(self, groups, mesh_of, pxr, scene_path, key):
        self.scene_path, self.key = scene_path, key
        self.blocks, self.roots, self.block_faces, self.block_slots = [], [], [], []
        faces, uvs, per_tri, found, offset, face0 = [], [], [], [], 0, 0
        self.notes = []
        for proxies in groups:
            mesh = mesh_of(proxies[0])
            roots = [instance_root(p) for p in proxies]
            self.blocks.append((mesh, roots[0], np.arange(len(proxies)), offset))
            self.roots.append(roots)
            faces.append(mesh.faces + offset)
            self.block_faces.append((face0, face0 + len(mesh.faces)))
            self.block_slots.append(None)
            if mesh.uvs is not None:
                uvs.append((offset, mesh.uvs))
            tri, mats = mesh.materials
            per_tri.append(material_slots(tri, mats, found))
            self.notes += mesh.notes
            offset += mesh.n_vertices
            face0 += len(mesh.faces)
        self.groups = groups
        self.proxies = [p for proxies in groups for p in proxies]
        self.n_vertices = offset
        self.faces = np.ascontiguousarray(np.concatenate(faces), np.int32)
        self.uvs = joined_uvs(uvs, offset)
        self.materials = (np.concatenate(per_tri).astype(np.int64), found)
        self.plain = np.zeros(face0, bool)
        self.skinning = None
        moving = any(pxr.UsdGeom.Xformable(p).TransformMightBeTimeVarying()
                     for roots in self.roots for r in roots for p in _ancestors(r) if p.IsA(pxr.UsdGeom.Xformable))
        self.static = not moving and all(b[0].static for b in self.blocks)
        self.rigid = False

    def evaluate(self, pxr, time, xform_cache):
        """Each group's mesh once, in its first instance root's space (the
        prototype's own transforms are every instance's)."""
        return np.concatenate([mesh.evaluate(pxr, time, xform_cache, relative_to=root)
                               for mesh, root, _, _ in self.blocks])

    def instance_matrices(self, pxr, time, xform_cache):
        """Per group, its copies' (n, 3, 4) world-from-instance-root matrices."""
        out = []
        for roots in self.roots:
            world = np.stack([_matrix(xform_cache.GetLocalToWorldTransform(r))[0] for r in roots])
            m = np.empty((len(roots), 3, 4))
            m[:, :, :3] = np.transpose(world[:, :3, :3], (0, 2, 1))
            m[:, :, 3] = world[:, 3, :3]
            if not np.all(np.isfinite(m)):
                raise SceneError(self.scene_path, self.key, f"an instance's transform is inf or NaN at time code "
                                                            f"{time.GetValue():g}")
            out.append(m)
        return out
