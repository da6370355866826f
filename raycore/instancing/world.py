"""An instanced world's structures: the prototypes' trees built once (and
refit when they deform), and a top-level tree over the instances' world
boxes, rebuilt every frame.

The frame's triangles (Geometry) hold every object once: the objects placed
in the world as they are, and each instanced object's prototype in its own
space. All of them live in one set of trees (bvh/scene.SceneBvh: a tree per
moving object, one for the static ones, one per prototype); the world's
trees are instances under the identity, and each copy of a prototype is an
instance of its tree under its own transform. A ray reaching an instance in
the top level is carried into the instance's space (instancing/walk.py) and
walks the prototype's tree there: an affine map keeps a packet's common
origin and its frustum, and a ray's t, so packets and closest hits work
unchanged. Memory per instance: two 3x4 matrices, its tree id and the top
level's two nodes (~200 bytes); none per copied triangle.
"""
from typing import NamedTuple

import numba
import numpy as np

from raycore.bvh.build import build_region
from raycore.bvh.nodes import empty_bvh
from raycore.bvh.scene import SceneBvh
from raycore.geometry.mesh import gather_some_triangles, gather_triangles, vertex_normals, vertex_normals_of
from raycore.instancing.accel import InstancedAccel
from raycore.jit.presets import parallel_kernel

# an instance's world box is widened by this fraction of its largest
# coordinate: the box is made from the prototype's box in float64, and the
# rays are tested against the prototype in its own space after a float32
# transform, whose rounding must not let a ray that hits there miss the box here
BOX_PAD = 2.0 ** -18


class InstanceFrame(NamedTuple):
    """The instances of one frame (prototype = a face range of the frame's Geometry)."""
    ranges: np.ndarray       # (P, 2) int64: each prototype's faces [first, end) in Geometry.faces
    moving: np.ndarray       # (P,) bool: the prototype deforms (its tree is refit every frame)
    proto: np.ndarray        # (N,) int32: each instance's prototype
    matrices: np.ndarray     # (N, 3, 4) float64: world from object (a zero 3x3: hidden)
    material: np.ndarray     # (N,) int32: the instance's material, -1: its prototype's
    id_base: np.ndarray      # (N,) int64: primitive id of the copy's first triangle (the flattened world's)
    tri_shift: np.ndarray    # (n_t,) int64: added to a world triangle's index for its primitive id
    plain: np.ndarray = None  # (n_t,) bool: an instance's own material replaces this triangle's (None: none do)


class Placement(NamedTuple):
    """Every instance the traversal sees (the world's trees under the identity first)."""
    tree: np.ndarray         # (M,) int64: root node of the instance's tree
    inverse: np.ndarray      # (M, 12) f32: rows [L^-1 | 0]; object from world is p -> L^-1 (p - origin)
    forward: np.ndarray      # (M, 12) f32: world from object
    identity: np.ndarray     # (M,) bool
    material: np.ndarray     # (M,) int32
    id_base: np.ndarray      # (M,) int64
    origin: np.ndarray       # (M, 3) float64: T, the instance's translation (rays map by L^-1 (p - T))


@parallel_kernel
def instance_boxes(root_box, tree_of, forward, pad, bounds):
    """World box (6) of each instance: its tree's root box
    (root_box[tree_of[j]]) under forward[j], in float64, widened by pad of
    its largest coordinate."""
    for j in numba.prange(tree_of.shape[0]):
        b = root_box[tree_of[j]]
        m = forward[j].astype(np.float64)
        for a in range(3):
            lo, hi = np.inf, -np.inf
            for corner in range(8):
                x = np.float64(b[3 if corner & 1 else 0])
                y = np.float64(b[4 if corner & 2 else 1])
                z = np.float64(b[5 if corner & 4 else 2])
                w = m[4 * a] * x + m[4 * a + 1] * y + m[4 * a + 2] * z + m[4 * a + 3]
                lo = min(lo, w)
                hi = max(hi, w)
            bounds[j, a] = lo
            bounds[j, 3 + a] = hi
        big = np.float32(0.0)
        for q in range(6):
            big = max(big, abs(bounds[j, q]))
        for a in range(3):
            bounds[j, a] -= np.float32(pad) * big
            bounds[j, 3 + a] += np.float32(pad) * big


@parallel_kernel
def invert_instances(matrices, proto, proto_tree, node_lo, tree, inverse, forward, origin, shown):
    """Per instance j (matrices[j]: world from object, a 3x4's rows, float64):
    its tree's root, its inverse and itself as float32 rows, and whether it
    is shown: a prototype with a tree, an invertible matrix, an inverse
    finite in float32 (a copy scaled to nothing is hidden, as a hidden
    copy's zero matrix is). The inverse's rows hold the inverse 3x3 L^-1
    (their 4th column 0), and origin[j] the translation T in float64: a
    point maps to L^-1 (p - T), its subtraction in float64, so that the copy is where its
    matrix puts it however far from the world's origin (a 3x4 inverse's
    -L^-1 T cancels against L^-1 p and loses the digits of both: depth 0.4 %
    out 10^5 units away, where flattened copies are 0.01 % out)."""
    for j in numba.prange(proto.shape[0]):
        m = matrices[j]
        a, b, c = m[0], m[1], m[2]
        d, e, f = m[4], m[5], m[6]
        g, h, i = m[8], m[9], m[10]
        c00, c01, c02 = e * i - f * h, c * h - b * i, b * f - c * e
        c10, c11, c12 = f * g - d * i, a * i - c * g, c * d - a * f
        c20, c21, c22 = d * h - e * g, b * g - a * h, a * e - b * d
        det = a * c00 + b * c10 + c * c20
        t = proto_tree[proto[j]]
        ok = det != 0.0 and t >= 0
        r = 1.0 / det if ok else 0.0
        lin = (c00 * r, c01 * r, c02 * r, c10 * r, c11 * r, c12 * r, c20 * r, c21 * r, c22 * r)
        origin[j, 0], origin[j, 1], origin[j, 2] = m[3], m[7], m[11]
        for row in range(3):
            inverse[j, 4 * row] = lin[3 * row]
            inverse[j, 4 * row + 1] = lin[3 * row + 1]
            inverse[j, 4 * row + 2] = lin[3 * row + 2]
            inverse[j, 4 * row + 3] = 0.0
        for q in range(12):
            forward[j, q] = m[q]
            ok = ok and np.isfinite(inverse[j, q])
        shown[j] = ok
        tree[j] = node_lo[t] if t >= 0 else -1


class InstancedStructures:
    """The structures of an instanced world, kept from frame to frame: the
    frame's triangle corners and vertex normals (every object once, the
    prototypes in their own space), the trees, and the top level.
    ranges, moving: the prototypes' face ranges and whether each deforms
    (as InstanceFrame has them); world_ranges: (first, end) face ranges of
    the world's moving objects (one tree each); every other world triangle
    in one static tree."""

    def __init__(self, faces, n_vertices, vf_start, vf_faces, ranges, moving, world_ranges=()):
        self.faces, self.vf_start, self.vf_faces = faces, vf_start, vf_faces
        n = faces.shape[0]
        self.tri_verts = np.empty((n, 9), np.float32)
        self.normals = np.empty((n_vertices, 3), np.float32)
        in_world = np.ones(n, bool)
        for s, e in ranges:
            in_world[s:e] = False
        groups, deforms = [], []
        for s, e in world_ranges:
            groups.append(np.arange(s, e, dtype=np.int32))
            deforms.append(True)
            in_world[s:e] = False
        groups.append(np.nonzero(in_world)[0].astype(np.int32))
        deforms.append(False)
        n_world = len(groups)
        for (s, e), m in zip(ranges, moving):
            groups.append(np.arange(s, e, dtype=np.int32))
            deforms.append(bool(m))
        # after the first frame only the moving triangles (the world's moving objects, deforming
        # prototypes) are gathered again and their vertices given normals again: a large static
        # set among the copies costs nothing per frame
        still = np.ones(n, bool)
        for g, m in zip(groups, deforms):
            if m:
                still[g] = False
        self.moving_tris = np.ascontiguousarray(np.nonzero(~still)[0], np.int32)
        self.moving_vertices = np.ascontiguousarray(np.unique(faces[self.moving_tris]), np.int32)
        self.packed = np.empty((len(self.moving_tris), 9), np.float32)
        self.gathered = self.normals_done = False
        # SceneBvh keeps the groups with triangles: its tree k is groups[kept[k]]
        kept = [g for g, tris in enumerate(groups) if len(tris)]
        self.trees = SceneBvh(n, groups, deforms, faces)
        tree_of_group = {g: k for k, g in enumerate(kept)}
        self.world_trees = np.array([tree_of_group[g] for g in range(n_world) if g in tree_of_group], np.int64)
        # a prototype without triangles has no tree: its instances are left out
        self.proto_tree = np.array([tree_of_group.get(n_world + p, -1) for p in range(len(ranges))], np.int64)
        self.top = None
        self.stats = {}

    def lazy_normals(self, n_pixels):
        return False

    def normals_now(self):
        """The vertex normals of this frame: all at the first, then the moving vertices'."""
        if self.normals_done:
            vertex_normals_of(self.moving_vertices, self.tri_verts, self.vf_start, self.vf_faces, self.normals)
        else:
            vertex_normals(self.tri_verts, self.vf_start, self.vf_faces, self.normals)
            self.normals_done = True
        return self.normals

    def placement(self, frame: InstanceFrame) -> Placement:
        """Every instance the top level holds this frame: the world's trees,
        then the visible copies (an invertible matrix whose inverse is
        finite in float32) of prototypes with triangles."""
        k, n = len(self.world_trees), len(frame.proto)
        tree = np.empty(k + n, np.int64)
        inverse = np.empty((k + n, 12), np.float32)
        forward = np.empty((k + n, 12), np.float32)
        origin = np.zeros((k + n, 3), np.float64)
        tree[:k] = self.trees.node_lo[self.world_trees]
        inverse[:k] = forward[:k] = np.eye(3, 4, dtype=np.float32).reshape(12)
        shown = np.empty(n, np.bool_)
        invert_instances(frame.matrices.reshape(n, 12), frame.proto, self.proto_tree, self.trees.node_lo,
                         tree[k:], inverse[k:], forward[k:], origin[k:], shown)
        ids = np.nonzero(shown)[0]
        m = k + len(ids)
        if len(ids) < n:                   # the hidden copies left out
            tree[k:m], inverse[k:m], forward[k:m] = tree[k:][ids], inverse[k:][ids], forward[k:][ids]
            origin[k:m] = origin[k:][ids]
        material = np.empty(m, np.int32)
        material[:k], material[k:] = -1, frame.material[ids]
        id_base = np.zeros(m, np.int64)
        id_base[k:] = frame.id_base[ids]
        identity = np.zeros(m, np.bool_)
        identity[:k] = True
        return Placement(tree[:m], inverse[:m], forward[:m], identity, material, id_base, origin[:m])

    def update(self, vertices, frame: InstanceFrame):
        """This frame's trees and top level: (tri_verts, trees' Bvh, top Bvh, Placement)."""
        if self.gathered:
            gather_some_triangles(vertices, self.faces, self.moving_tris, self.tri_verts, self.packed)
        else:
            gather_triangles(vertices, self.faces, self.tri_verts)
            self.gathered = True
        bvh = self.trees.update(self.tri_verts, vertices)
        self.stats = dict(self.trees.stats)
        place = self.placement(frame)
        m = len(place.tree)
        if self.top is None or self.top.tri.shape[0] < m:
            self.top = empty_bvh(max(2 * m, 1), max(m, 1))
        top = self.top
        if m == 0:
            top.box[0, :3], top.box[0, 3:] = np.inf, -np.inf
            top.child[0], top.count[0] = -1, 0
        else:
            bounds = np.empty((m, 6), np.float32)
            instance_boxes(bvh.box, place.tree, place.forward, BOX_PAD, bounds)
            order = np.empty(m, np.int32)
            build_region(bounds, 1, 0, 0, top.box, top.child, top.count, order,
                         numba.get_num_threads())
            top.tri[:m] = order
        self.stats["instances"] = m - len(self.world_trees)
        return self.tri_verts, bvh, top, place

    def build(self, names, geom, cfg, buffers, counters, lazy_corners=False) -> tuple:
        """(tri_verts, {name: accelerator}): one two-level structure serves
        every name asked for (camera and shadow rays). lazy_corners is
        FrameStructures.build's; an instanced world always gathers its
        corners (its normals are never lazy)."""
        tri_verts, bvh, top, place = self.update(geom.vertices, geom.instances)
        counters.update(self.stats)
        accel = InstancedAccel(top, bvh, place, buffers.work)
        return tri_verts, {name: accel for name in names}
