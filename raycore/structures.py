"""The per-frame structures of one scene, kept from frame to frame: the
triangles' corners and vertex normals, the uniform grid, the BVH's trees and
the kd-tree, each made only when a frame asks for it, leaving out static work.

Static triangles never change, so after the first frame only the moving ones
are gathered and given normals, and the grid bins them alone
(grid/incremental.py); the BVH refits per moving object (bvh/scene.py); a
kd-tree is kept when nothing ever moves (a fly-through).
"""
import numba
import numpy as np

from raycore.accelerators import BvhAccel, GridAccel, KdAccel
from raycore.bvh.scene import SceneBvh
from raycore.geometry.mesh import (gather_some_triangles, gather_triangles, mark_hit_vertices, vertex_normals,
                                   vertex_normals_of, wanted_vertex_normals)
from raycore.grid.build import Grid, finite_bounds
from raycore.grid.incremental import MIN_STATIC_SHARE, IncrementalGrid, full_grid
from raycore.kdtree.build import build_kdtree


class FrameStructures:
    """Per-frame geometry of one scene. `moving_tris`: ids of the triangles
    whose vertices may move (None: all of them)."""

    def __init__(self, faces, n_vertices, vf_start, vf_faces, density, moving_tris=None, object_ranges=None):
        """object_ranges: (first, end) triangle ranges of the moving objects,
        one BVH tree each (bvh/scene.py); None: all moving triangles in one."""
        self.faces, self.vf_start, self.vf_faces = faces, vf_start, vf_faces
        self.moving_tris, self.object_ranges = moving_tris, object_ranges
        self.bvh = None
        self.vertices = None          # the last update's vertices
        self.stale = False            # tri_verts not gathered for them (build's lazy corners)
        self.density = density
        n = faces.shape[0]
        self.tri_verts = np.empty((n, 9), np.float32)
        self.normals = np.empty((n_vertices, 3), np.float32)
        self.normal_state = None      # per vertex: 0 none, 1 wanted, 2 made (lazy_normals)
        self.incremental = moving_tris is not None and n - len(moving_tris) >= MIN_STATIC_SHARE * n
        if self.incremental:
            moving = np.zeros(n, bool)
            moving[moving_tris] = True
            self.moving = np.ascontiguousarray(np.nonzero(moving)[0], np.int32)
            self.static = np.ascontiguousarray(np.nonzero(~moving)[0], np.int32)
            self.moving_vertices = np.ascontiguousarray(np.unique(faces[self.moving]), np.int32)
            self.packed = np.empty((len(self.moving), 9), np.float32)
            self.grid_bins = IncrementalGrid(self.static, self.moving, density)
        self.first = True
        self.normals_done = False
        self.kd_tree = None         # kept by build() when nothing moves
        self.static_bounds = None

    def scene_bvh(self):
        """The scene's BVH trees (made on first use, kept across frames)."""
        if self.bvh is None:
            self.bvh = SceneBvh.of_objects(self.faces.shape[0], self.object_ranges, self.moving_tris, self.faces)
        return self.bvh

    @property
    def all_static(self):
        """True when no triangle of the scene ever moves (the camera may)."""
        return self.incremental and len(self.moving) == 0

    def lazy_normals(self, n_pixels):
        """Whether this frame's vertex normals are better made for the
        vertices that are seen (normals_for) than for all: a scene that
        moves whole, with more vertices than twice the pixels (at 10M
        triangles all of them took 120 ms a frame, for a million pixels)."""
        return not self.incremental and self.normals.shape[0] > 2 * n_pixels

    def forget_normals(self):
        """A new frame's vertices: no normal made yet (for normals_for)."""
        if self.normal_state is None:
            self.normal_state = np.zeros(self.normals.shape[0], np.uint8)
        else:
            self.normal_state.fill(0)

    def normals_for(self, prim):
        """The vertex normals, made now for the vertices of the hit triangles
        prim that have none yet (after forget_normals); when the frame's
        corners were left ungathered (build's lazy corners), the hit
        triangles' corners gathered now, the only ones shading reads."""
        mark_hit_vertices(prim.reshape(-1), self.faces, self.normal_state, self.vertices, self.tri_verts, self.stale)
        wanted_vertex_normals(self.normal_state, self.vertices, self.faces, self.vf_start, self.vf_faces,
                              self.normals)
        return self.normals

    def corners(self):
        """The frame's triangle corners, all of them (gathered now if the
        build left them: a full build of the BVH's trees reads them all)."""
        if self.stale:
            gather_triangles(self.vertices, self.faces, self.tri_verts)
            self.stale = False
        return self.tri_verts

    def normals_now(self):
        """Vertex normals of the triangles of the last update (moving ones
        only, after the first frame)."""
        if self.incremental and self.normals_done:
            vertex_normals_of(self.moving_vertices, self.tri_verts, self.vf_start, self.vf_faces, self.normals)
        else:
            vertex_normals(self.tri_verts, self.vf_start, self.vf_faces, self.normals)
            self.normals_done = True
        return self.normals

    def gather(self, vertices):
        """This frame's triangle corners (n, 9) f32: all of them, or after the
        first frame only the moving ones (also packed into self.packed)."""
        threads = numba.get_num_threads()
        self.vertices, self.stale = vertices, False
        if not self.incremental:
            gather_triangles(vertices, self.faces, self.tri_verts)
            return self.tri_verts
        if self.first:
            gather_triangles(vertices, self.faces, self.tri_verts)
            self.static_bounds = finite_bounds(self.tri_verts[self.static], None, threads)
            self.first = False
        gather_some_triangles(vertices, self.faces, self.moving, self.tri_verts, self.packed)
        return self.tri_verts

    def update(self, vertices) -> tuple:
        """(grid, tri_verts) for this frame's vertex positions."""
        self.gather(vertices)
        if not self.incremental:
            return full_grid(self.tri_verts, vertices, self.density), self.tri_verts
        grid: Grid = self.grid_bins.update(self.tri_verts, self.packed, self.static_bounds)
        return grid, self.tri_verts

    def build(self, names, geom, cfg, buffers, counters, lazy_corners=False) -> tuple:
        """(tri_verts, {name: accelerator}) for this frame's vertices: the
        triangles gathered once, then each named structure built (grid, kd-tree)
        or updated (the BVH's refit trees, bvh/scene.py) over them.

        lazy_corners (a caller that reads tri_verts only through
        normals_for's hits): when the BVH alone is asked for, its trees are
        built and the normals are lazy, the corners are not gathered at all
        (the refit reads the vertices): normals_for gathers the hit
        triangles' and corners() all of them. At 10M triangles the gather
        wrote 360 MB a frame (38-43 ms) for the ~0.5M triangles a
        million-pixel image sees."""
        built = {}
        if (lazy_corners and set(names) == {"bvh"} and self.bvh is not None and not self.bvh.first
                and self.lazy_normals(cfg.width * cfg.height)):
            self.vertices, self.stale = geom.vertices, True
            trees = self.bvh
            built["bvh"] = BvhAccel(trees.update(self.tri_verts, geom.vertices, corners=self.corners),
                                    self.tri_verts, buffers.work)
            counters.update(trees.stats)
            return self.tri_verts, built
        if "grid" in names:
            grid, tri_verts = self.update(geom.vertices)
            counters["grid_dims"] = [int(d) for d in grid.dims]
            built["grid"] = GridAccel(grid, tri_verts, cfg.packet, cfg.grid_cull, buffers.camera)
        else:
            tri_verts = self.gather(geom.vertices)
        if "kdtree" in names:
            tree = self.kd_tree
            if tree is None:
                tree = build_kdtree(tri_verts)
                if self.all_static:           # a fly-through: build the tree once
                    self.kd_tree = tree
            counters["kd_nodes"] = int(len(tree.axis))
            built["kdtree"] = KdAccel(tree, tri_verts)
        if "bvh" in names:
            trees = self.scene_bvh()
            built["bvh"] = BvhAccel(trees.update(tri_verts, geom.vertices), tri_verts, buffers.work)
            counters.update(trees.stats)
        return tri_verts, built
