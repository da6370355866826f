"""The uniform grid of consecutive frames, leaving out static work.

Most animated scenes are a large still set with a few moving objects. Their
static triangles never change, so their grid cells are binned once; each
frame bins only the moving triangles and merges the two cell lists cell by
cell (a copy, no binning). With few static triangles the merge copy costs
more than it saves, so the owner of the frame's triangles
(raycore/structures.py) takes this path only when at least
MIN_STATIC_SHARE of them are static (docs/performance.md, the incremental grid).

The static cell lists depend on the grid's box, so they are rebuilt when the
moving objects leave the static box (the box grows). Every frame lists a
cell's static triangles first, then its moving ones, whichever path built it:
a frame renders the same bytes alone or in a sequence.
"""
import numba
import numpy as np

from raycore.grid.build import Grid, bin_triangles, finite_bounds, grid_shape, merge_cells, point_bounds

MIN_STATIC_SHARE = 0.3


def _union(a, b):
    return np.minimum(a[0], b[0]), np.maximum(a[1], b[1])


def _grid(shape, start, tris):
    return Grid(shape.lo, shape.hi, shape.dims, shape.cell_size, shape.inv_cell, start, tris)


def full_grid(tri_verts, vertices, density) -> Grid:
    """Every triangle of tri_verts (n, 9) binned afresh; `vertices` bound the box."""
    threads = numba.get_num_threads()
    bounds = point_bounds(vertices, threads) if len(vertices) else None
    lo, hi = finite_bounds(tri_verts, bounds, threads)
    shape = grid_shape(lo, hi, len(tri_verts), density)
    start, tris = bin_triangles(tri_verts, shape, threads)
    return _grid(shape, start, tris)


class IncrementalGrid:
    """The grid over static triangles (binned once per box) and moving ones
    (binned each frame). static, moving: (k,) i32 triangle ids."""

    def __init__(self, static, moving, density):
        self.static, self.moving, self.density = static, moving, density
        self.static_shape = self.static_cells = None

    def update(self, tri_verts, packed, static_bounds) -> Grid:
        """This frame's grid: tri_verts (n, 9) all corners, packed (k, 9) the
        moving triangles' corners, static_bounds the static triangles' box."""
        threads = numba.get_num_threads()
        bounds = static_bounds
        if len(self.static) == 0:
            bounds = finite_bounds(packed, None, threads)
        elif len(self.moving):
            moving_box = finite_bounds(packed, None, threads)
            bounds = _union(bounds, moving_box)
        shape = grid_shape(bounds[0], bounds[1], len(tri_verts), self.density)
        if not shape.same_as(self.static_shape):
            start, tris = bin_triangles(tri_verts[self.static], shape, threads)
            self.static_shape, self.static_cells = shape, (start, self.static[tris])
        s_start, s_tris = self.static_cells
        if len(self.moving) == 0:
            return _grid(shape, s_start, s_tris)
        m_start, m_tris = bin_triangles(packed, shape, threads)
        start = np.empty_like(s_start)
        tris = np.empty(len(s_tris) + len(m_tris), np.int32)
        merge_cells(s_start, s_tris, m_start, m_tris, self.moving, start, tris)
        return _grid(shape, start, tris)
