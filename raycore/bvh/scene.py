"""One BVH per frame, kept up to date with the least work: a tree per moving
object, refit every frame, one tree for all static objects, built once, and
a small top-level tree over their roots, built every frame.

Keyframed meshes keep their topology, so each moving object's tree is built
once and then refit (bvh/refit.py): its boxes follow the
vertices. Refitting keeps the tree's shape, which suits rigid and gently
deforming motion; when an object's parts move apart, its boxes grow and
overlap, so the SAH cost of every refit tree is compared with its cost at
the last build, and the tree is rebuilt once it has grown by REBUILD_GROWTH.
Static objects (a ground, a set) never change and are gathered into one
tree; the top level over the trees' roots costs microseconds, and it keeps a
detailed object inside a large set from crowding the set's nodes (the
teapot in a stadium, which a uniform grid suffers from).

All trees live in one set of arrays (nodes.Bvh): the top level in
nodes 0..2G-1 (G trees), then each tree's region of 2m nodes and m
references (m triangles). A leaf of the top level is a copy of a tree's root
node, so a traversal sees one tree and never asks which part it is in.
"""
import time

import numba
import numpy as np

from raycore.bvh.build import (PARALLEL_ROWS, SMALL_TREE, build_region, build_region_of_tris, build_small_trees,
                               gather_references, on_parts)
from raycore.bvh.nodes import MAX_LEAF, Bvh, empty_bvh
from raycore.bvh.refit import REFIT_PIECES, refit, refit_plan
from raycore.jit.thread_pool import on_threads
from raycore.jit.tile_queue import new_queue

# a refit tree is rebuilt when its SAH cost exceeds this many times its cost
# at the last build. The SAH cost is the expected work of a ray, so a tree
# grown by g costs about (g - 1) x its traversal time more every frame: where
# a build costs a third of a frame's shadow traversal (hand), from g = 1.3 on
# one frame's extra work pays for the rebuild. Most built-in scenes' refit
# trees stay below 1.22; the tumbling marbles' reach 1.48, where 1.3 and 1.5
# measured alike (docs/performance.md).
REBUILD_GROWTH = 1.3
# small trees (bvh/build.SMALL_TREE) built at once, at the first frame or
# rebuilt in one, go through one call (build_small_trees) from this many on:
# one by one they cost ~25 us each of Python and dispatch, and that call's
# kernel compiles in ~2.2 s, which scenes of few objects never pay
BATCH_TREES = 8


class SceneBvh:
    """groups: one int32 array of triangle ids per tree; moving[g] says whether
    tree g must follow the vertices every frame; faces (n_tris, 3): the
    mesh's vertex ids of each triangle (None: a soup, triangle t's corners
    are vertices 3t..3t+2 of tri_verts read as (3n, 3))."""

    def __init__(self, n_tris, groups, moving, faces=None):
        kept = [(np.ascontiguousarray(g, np.int32), bool(m)) for g, m in zip(groups, moving) if len(g)]
        self.groups = [g for g, _ in kept]
        self.moving = [m for _, m in kept]
        groups = self.groups
        n_groups = len(groups)
        self.top_nodes = max(2 * n_groups, 1)
        self.node_lo = np.zeros(n_groups, np.int64)
        self.ref_lo = np.zeros(n_groups, np.int64)
        node, ref = self.top_nodes, 0
        for g, tris in enumerate(groups):
            self.node_lo[g], self.ref_lo[g] = node, ref
            node += 2 * len(tris)
            ref += len(tris)
        self.bvh = empty_bvh(node, ref)
        self.soup = faces is None
        self.faces = (np.arange(3 * n_tris, dtype=np.int32).reshape(n_tris, 3) if faces is None
                      else np.ascontiguousarray(faces, np.int32))
        self.leaf_faces = np.zeros((ref, 3), np.int32)     # the faces of bvh.tri, for the refit
        self.built_cost = np.zeros(n_groups, np.float32)
        self.cost = np.zeros(n_groups, np.float32)
        self.first = True
        self.stats = {}
        self._moving_idx = np.array([g for g in range(n_groups) if self.moving[g]], np.int64)
        self._moving_roots = np.ascontiguousarray(self.node_lo[self._moving_idx])
        self._moving_cost = np.empty(len(self._moving_idx), np.float32)
        self.used = np.zeros(n_groups, np.int64)     # nodes each tree's build used
        # every tree's triangles in one array (tree g's: all_tris[tri_start[g]:tri_start[g + 1]])
        self.tri_start = np.zeros(n_groups + 1, np.int64)
        np.cumsum([len(g) for g in groups], out=self.tri_start[1:])
        # (one tree: its own array, not a copy, 4 bytes a triangle)
        self.all_tris = (groups[0] if len(groups) == 1 else np.concatenate(groups) if groups
                         else np.zeros(0, np.int32))
        # the moving trees' refit plans (refit.refit_plan) in fixed slots,
        # REFIT_PIECES pieces and REFIT_PIECES - 1 top nodes a tree (-1: unused),
        # rewritten by a tree's build: no joining of 110 marbles' plans per frame
        n_moving = len(self._moving_idx)
        self.slot = {int(g): j for j, g in enumerate(self._moving_idx)}
        self.front = np.full(n_moving * REFIT_PIECES, -1, np.int64)
        self.front_end = np.zeros(n_moving * REFIT_PIECES, np.int64)
        self.tops = np.full(n_moving * (REFIT_PIECES - 1), -1, np.int64)
        self.front_start = np.arange(n_moving + 1, dtype=np.int64) * REFIT_PIECES
        self.tops_start = np.arange(n_moving + 1, dtype=np.int64) * (REFIT_PIECES - 1)
        self.part = np.empty(n_moving * REFIT_PIECES)

    @classmethod
    def of_objects(cls, n_tris, object_ranges=None, moving_tris=None, faces=None):
        """Trees for a scene: object_ranges (start, end) face ranges of the
        moving objects, one tree each; every other triangle in one static
        tree. Without object_ranges, moving_tris (None: all) are one tree.
        faces: as in SceneBvh."""
        is_moving = np.zeros(n_tris, bool)
        groups, moving = [], []
        if object_ranges is not None:
            for s, e in object_ranges:
                groups.append(np.arange(s, e, dtype=np.int32))
                moving.append(True)
                is_moving[s:e] = True
        else:
            ids = np.arange(n_tris, dtype=np.int32) if moving_tris is None else np.asarray(moving_tris, np.int32)
            groups.append(ids)
            moving.append(True)
            is_moving[ids] = True
        groups.append(np.nonzero(~is_moving)[0].astype(np.int32))
        moving.append(False)
        return cls(n_tris, groups, moving, faces)

    def _build(self, tri_verts, g):
        """Build tree g into its region from this frame's triangle corners."""
        tris = self.groups[g]
        m = len(tris)
        order = np.empty(m, np.int32)
        b = self.bvh
        n0, r0 = int(self.node_lo[g]), int(self.ref_lo[g])
        used, cost = build_region_of_tris(tri_verts, tris, MAX_LEAF, n0, r0, b.box, b.child, b.count, order,
                                          numba.get_num_threads())
        # the region's nodes past `used` are never reached (nor written: untouched, they take no memory)
        on_parts(gather_references, m, numba.get_num_threads() if m >= PARALLEL_ROWS else 1, tris, order,
                 tri_verts, self.faces, r0, b.tri, b.verts, self.leaf_faces)
        self.built_cost[g] = self.cost[g] = cost
        self.used[g] = used
        if self.moving[g]:
            self._set_plan(g, *refit_plan(b.child, b.count, n0, used))

    def _set_plan(self, g, front, ends, tops):
        """Moving tree g's refit plan into its slots."""
        j = self.slot[g]
        p0, t0 = self.front_start[j], self.tops_start[j]
        self.front[p0:self.front_start[j + 1]], self.tops[t0:self.tops_start[j + 1]] = -1, -1
        self.front[p0:p0 + len(front)], self.front_end[p0:p0 + len(front)] = front, ends
        self.tops[t0:t0 + len(tops)] = tops

    def _build_trees(self, tri_verts, trees):
        """Build trees `trees` (ids): the small ones in one call when there
        are BATCH_TREES of them (the same trees bit for bit), the others
        one by one."""
        sizes = self.tri_start[1:] - self.tri_start[:-1]
        small = [g for g in trees if sizes[g] < SMALL_TREE]
        if len(small) < BATCH_TREES:
            small = []
        for g in trees:
            if sizes[g] >= SMALL_TREE or not small:
                self._build(tri_verts, g)
        if not small:
            return
        which = np.array(small, np.int64)
        used = np.empty(len(which), np.int64)
        cost = np.empty(len(which), np.float32)
        ends = np.empty(len(which), np.int64)
        b = self.bvh
        on_threads(build_small_trees, min(numba.get_num_threads(), len(which)), tri_verts, self.faces,
                   self.all_tris, self.tri_start, which, self.node_lo, self.ref_lo, MAX_LEAF, b.node, b.node_i, b.tri,
                   b.verts, self.leaf_faces, used, cost, ends, new_queue())
        self.built_cost[which] = self.cost[which] = cost
        self.used[which] = used
        empty = np.zeros(0, np.int64)
        for g, n0, end in zip(small, self.node_lo[which], ends):
            if self.moving[g]:
                self._set_plan(g, np.array([n0], np.int64), np.array([end], np.int64), empty)

    def build_all(self, tri_verts):
        """Build every tree anew from these triangle corners (the first
        frame; bench times it)."""
        self._build_trees(tri_verts, list(range(len(self.groups))))
        self.first = False

    def update(self, tri_verts, vertices=None, corners=None) -> Bvh:
        """The tree of this frame's triangle corners tri_verts (n, 9), which
        are vertices[faces] (vertices None: a soup, see SceneBvh). corners:
        where tri_verts may be stale (FrameStructures.build's lazy corners),
        what gathers them, called before a tree is built again (a refit
        reads the vertices)."""
        t0 = time.perf_counter()
        n_built = 0
        if self.first:
            self.build_all(tri_verts)
            n_built = len(self.groups)
            build_ms = (time.perf_counter() - t0) * 1e3
            refit_ms = 0.0
            growth = 1.0
        else:
            idx = self._moving_idx
            if len(idx):
                self.refit_moving(tri_verts, vertices)
            refit_ms = (time.perf_counter() - t0) * 1e3
            growth = float(np.max(self.cost / np.maximum(self.built_cost, 1e-30))) if len(self.cost) else 1.0
            t1 = time.perf_counter()
            grown = [int(g) for g in idx if self.cost[g] > REBUILD_GROWTH * self.built_cost[g]]
            if grown:
                self._build_trees(tri_verts if corners is None else corners(), grown)
            n_built = len(grown)
            build_ms = (time.perf_counter() - t1) * 1e3
        t1 = time.perf_counter()
        self._top_level()
        self.stats = {"bvh_build_ms": build_ms, "bvh_refit_ms": refit_ms,
                      "bvh_top_ms": (time.perf_counter() - t1) * 1e3, "bvh_rebuilt": n_built,
                      # the largest SAH cost of a refit tree over its cost at its last build
                      "bvh_sah_growth": growth}
        return self.bvh

    def refit_moving(self, tri_verts, vertices=None):
        """Every moving tree's boxes refit to these positions (as update),
        their SAH costs into self.cost. On a SceneBvh without trees it does
        nothing but compile the refit for the frame's types (the cold
        cache's helper process, anim/render/compile_helper.py)."""
        b = self.bvh
        if self.soup:
            points = tri_verts.reshape(-1, 3)
        elif vertices is None:
            raise ValueError("a SceneBvh made with faces refits from the vertices: pass them")
        else:
            points = np.ascontiguousarray(vertices, np.float32)
        refit(points, self.front, self.front_end, self.front_start, self.tops, self.tops_start,
              self._moving_roots, b.node, b.node_i, self.leaf_faces, b.verts, self.part, self._moving_cost)
        self.cost[self._moving_idx] = self._moving_cost

    def _top_level(self):
        """Nodes 0..2G-1: a binned-SAH tree over the G roots; its leaves are
        copies of the roots."""
        b = self.bvh
        n_groups = len(self.groups)
        if n_groups == 0:
            b.box[0, :3] = np.inf
            b.box[0, 3:] = -np.inf
            b.child[0], b.count[0] = -1, 0
            return
        roots = self.node_lo
        bounds = np.ascontiguousarray(b.box[roots])
        order = np.empty(n_groups, np.int32)
        used, _ = build_region(bounds, 1, 0, 0, b.box, b.child, b.count, order, 1)
        b.child[used:self.top_nodes] = -1
        b.count[used:self.top_nodes] = 0
        leaves = np.nonzero(b.count[:used] > 0)[0]
        src = roots[order[b.child[leaves]]]
        b.node_i[leaves] = b.node_i[src]          # the whole row, bit for bit
