"""Uniform grid rebuilt every frame, in parallel (Wald et al. 2006, Sec. 3).

Three passes, no Python lists and no per-cell allocation:
1. count: each thread histograms the cells its slice of triangles overlaps;
2. scan: per-cell totals -> `cell_start`, and each thread's write offset per cell;
3. fill: each thread writes its triangle ids into its own offsets.
Threads never write the same slot, so no atomics are needed, and every cell
lists its triangles in ascending id order (deterministic output).

Triangles are inserted by their (slightly widened) bounding box; the traversal
culls the extra candidates against its frustum, which is cheaper than exact
triangle/box tests at build time.
"""
from typing import NamedTuple

import numpy as np
from numba import prange

from raycore.jit.presets import kernel, parallel_arith_kernel
from raycore.config import EPS_GRID_REL
from raycore.jit.floats import F0

MAX_CELLS = 1 << 24
MAX_DIM = 1024


class Grid(NamedTuple):
    """Flat uniform grid. Cell (ix, iy, iz) is `(iz * ny + iy) * nx + ix`."""
    lo: np.ndarray          # (3,) f32 lower corner
    hi: np.ndarray          # (3,) f32 upper corner
    dims: np.ndarray        # (3,) i32 cells per axis
    cell_size: np.ndarray   # (3,) f32
    inv_cell: np.ndarray    # (3,) f32
    cell_start: np.ndarray  # (n_cells + 1,) i32 CSR offsets into cell_tris
    cell_tris: np.ndarray   # (n_refs,) i32 triangle ids


@parallel_arith_kernel
def point_bounds(points, n_chunks):
    """Bounding box (lo (3,), hi (3,)) f32 of points (m, 3): pass the mesh
    vertices (fewer than triangle corners) or tri_verts.reshape(-1, 3).

    NaN coordinates are skipped by the comparisons; an infinite coordinate
    makes the box infinite and `build_grid` then takes the finite-only path.
    """
    m = points.shape[0]
    part = np.empty((n_chunks, 6), np.float32)
    for c in prange(n_chunks):
        lo0 = lo1 = lo2 = np.float32(np.inf)
        hi0 = hi1 = hi2 = np.float32(-np.inf)
        for i in range(c * m // n_chunks, (c + 1) * m // n_chunks):
            x = points[i, 0]
            y = points[i, 1]
            z = points[i, 2]
            lo0 = x if x < lo0 else lo0
            lo1 = y if y < lo1 else lo1
            lo2 = z if z < lo2 else lo2
            hi0 = x if x > hi0 else hi0
            hi1 = y if y > hi1 else hi1
            hi2 = z if z > hi2 else hi2
        part[c, 0] = lo0
        part[c, 1] = lo1
        part[c, 2] = lo2
        part[c, 3] = hi0
        part[c, 4] = hi1
        part[c, 5] = hi2
    lo = np.empty(3, np.float32)
    hi = np.empty(3, np.float32)
    # the chunks' boxes joined in a loop: .min() and .max() of a column
    # compiled numba's reductions (~1 s)
    for a in range(3):
        lo[a] = part[0, a]
        hi[a] = part[0, 3 + a]
        for c in range(1, n_chunks):
            lo[a] = min(lo[a], part[c, a])
            hi[a] = max(hi[a], part[c, 3 + a])
    return lo, hi


def _finite_bounds(tri_verts):
    """Slow path: bounds over the triangles whose 9 coordinates are finite."""
    ok = np.isfinite(tri_verts).all(axis=1)
    if not ok.any():
        return np.full(3, np.inf, np.float32), np.full(3, -np.inf, np.float32)
    pts = tri_verts[ok].reshape(-1, 3)
    return pts.min(axis=0), pts.max(axis=0)


def grid_dims(extent: np.ndarray, n_tris: int, density: float) -> np.ndarray:
    """Cells per axis so that n_cells ~= density * n_tris, cells ~cubic.

    Axes too thin for one cell get one, and the budget is re-spread over the
    others (a flat floor must not collapse the grid to a 1-cell slab).
    """
    target = max(1.0, density * max(n_tris, 1))
    ext = np.maximum(np.asarray(extent, np.float64), 0.0)
    free = ext > 0
    dims = np.ones(3, np.int64)
    for _ in range(3):
        if not free.any():
            break
        budget = target / np.prod(dims[~free]) if (~free).any() else target
        s = (budget / np.prod(ext[free])) ** (1.0 / free.sum())
        cells = ext * s
        thin = free & (cells < 1.0)
        if thin.any():
            free &= ~thin
            continue
        dims[free] = np.maximum(1, np.round(cells[free])).astype(np.int64)
        break
    dims = np.minimum(dims, MAX_DIM)
    while dims.prod() > MAX_CELLS:
        dims = np.maximum(1, dims // 2)
    return dims.astype(np.int32)




@kernel
def _cell_ranges(tri_verts, t0, t1, lo0, lo1, lo2, inv0, inv1, inv2, n0, n1, n2, pad, ranges):
    """ranges (6, n) i32 = inclusive cell index ranges (x0, y0, z0, x1, y1, z1)
    of the widened bboxes of triangles t0..t1-1; x1 = -1 (empty) for a
    triangle with a non-finite coordinate. Scalar parameters and SoA output so
    that LLVM vectorizes it across triangles (2x faster than row-wise)."""
    for t in range(t0, t1):
        total = F0
        for k in range(9):
            total += tri_verts[t, k]
        ok = abs(total) < np.float32(np.inf)       # NaN and inf propagate through the sum
        ax = (min(tri_verts[t, 0], tri_verts[t, 3], tri_verts[t, 6]) - pad - lo0) * inv0
        bx = (max(tri_verts[t, 0], tri_verts[t, 3], tri_verts[t, 6]) + pad - lo0) * inv0
        ay = (min(tri_verts[t, 1], tri_verts[t, 4], tri_verts[t, 7]) - pad - lo1) * inv1
        by = (max(tri_verts[t, 1], tri_verts[t, 4], tri_verts[t, 7]) + pad - lo1) * inv1
        az = (min(tri_verts[t, 2], tri_verts[t, 5], tri_verts[t, 8]) - pad - lo2) * inv2
        bz = (max(tri_verts[t, 2], tri_verts[t, 5], tri_verts[t, 8]) + pad - lo2) * inv2
        # int() of NaN is undefined: use 0 for non-finite triangles. Finite
        # ones lie inside the grid bounds, so their indices stay small;
        # truncation equals floor for f >= 0 and f < 0 clamps to 0 either way
        ranges[0, t] = min(max(np.int32(ax if ok else F0), 0), n0 - 1)
        ranges[1, t] = min(max(np.int32(ay if ok else F0), 0), n1 - 1)
        ranges[2, t] = min(max(np.int32(az if ok else F0), 0), n2 - 1)
        ranges[3, t] = min(max(np.int32(bx if ok else F0), 0), n0 - 1) if ok else -1
        ranges[4, t] = min(max(np.int32(by if ok else F0), 0), n1 - 1)
        ranges[5, t] = min(max(np.int32(bz if ok else F0), 0), n2 - 1)


@parallel_arith_kernel
def _fill(tri_verts, lo, inv_cell, dims, pad, n_chunks):
    n = tri_verts.shape[0]
    nx, ny, nz = dims[0], dims[1], dims[2]
    n_cells = nx * ny * nz
    ranges = np.empty((6, n), np.int32)
    # arrays are zeroed by loops inside the parallel ones: numba compiles an
    # np.zeros here into a parallel loop of its own (~1.5 s of first compile each)
    hist = np.empty((n_chunks, n_cells), np.int32)
    # 1. count, one histogram per chunk
    for c in prange(n_chunks):
        for cell in range(n_cells):
            hist[c, cell] = 0
        t0 = c * n // n_chunks
        t1 = (c + 1) * n // n_chunks
        _cell_ranges(tri_verts, t0, t1, lo[0], lo[1], lo[2], inv_cell[0], inv_cell[1],
                     inv_cell[2], nx, ny, nz, pad, ranges)
        for t in range(t0, t1):
            x0, y0, z0 = ranges[0, t], ranges[1, t], ranges[2, t]
            x1, y1, z1 = ranges[3, t], ranges[4, t], ranges[5, t]
            if x0 == x1 and y0 == y1 and z0 == z1:        # most triangles: one cell
                hist[c, (z0 * ny + y0) * nx + x0] += 1
                continue
            for iz in range(z0, z1 + 1):
                for iy in range(y0, y1 + 1):
                    row = (iz * ny + iy) * nx
                    for ix in range(x0, x1 + 1):
                        hist[c, row + ix] += 1
    # 2. scan: each chunk's write offset per cell, and the cells' starts, in
    # one serial pass (n_chunks is the thread count: two parallel loops here
    # cost ~1 s more of first compile and gained no time)
    cell_start = np.empty(n_cells + 1, np.int32)
    acc = 0
    for cell in range(n_cells):
        cell_start[cell] = acc
        for c in range(n_chunks):
            h = hist[c, cell]
            hist[c, cell] = acc
            acc += h
    cell_start[n_cells] = acc
    # 3. fill, each chunk into its own slots
    cell_tris = np.empty(acc, np.int32)
    for c in prange(n_chunks):
        for t in range(c * n // n_chunks, (c + 1) * n // n_chunks):
            x0, y0, z0 = ranges[0, t], ranges[1, t], ranges[2, t]
            x1, y1, z1 = ranges[3, t], ranges[4, t], ranges[5, t]
            if x0 == x1 and y0 == y1 and z0 == z1:
                cell = (z0 * ny + y0) * nx + x0
                cell_tris[hist[c, cell]] = t
                hist[c, cell] += 1
                continue
            for iz in range(z0, z1 + 1):
                for iy in range(y0, y1 + 1):
                    row = (iz * ny + iy) * nx
                    for ix in range(x0, x1 + 1):
                        cell_tris[hist[c, row + ix]] = t
                        hist[c, row + ix] += 1
    return cell_start, cell_tris


class GridShape(NamedTuple):
    """Where the cells are: everything of a Grid but its triangle lists."""
    lo: np.ndarray
    hi: np.ndarray
    dims: np.ndarray
    cell_size: np.ndarray
    inv_cell: np.ndarray
    pad: np.float32

    def same_as(self, other) -> bool:
        return (other is not None and np.array_equal(self.lo, other.lo)
                and np.array_equal(self.hi, other.hi) and np.array_equal(self.dims, other.dims))


def grid_shape(lo, hi, n_tris: int, density: float) -> GridShape:
    """Cells for n_tris triangles inside the finite box (lo, hi), widened a
    little so that no triangle touches the outer faces."""
    lo64, hi64 = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    extent = hi64 - lo64
    size = max(float(extent.max()), float(np.abs(np.concatenate([lo64, hi64])).max()) * 1e-6, 1e-30)
    pad = EPS_GRID_REL * size
    lo64 = lo64 - 2 * pad
    hi64 = hi64 + 2 * pad
    dims = grid_dims(hi64 - lo64 - 4 * pad, n_tris, density)
    cell = (hi64 - lo64) / dims
    return GridShape(lo64.astype(np.float32), hi64.astype(np.float32), dims, cell.astype(np.float32),
                     (1.0 / cell).astype(np.float32), np.float32(pad))


def finite_bounds(tri_verts, bounds, n_chunks):
    """`bounds` if given and finite, else the box of the finite triangles (a
    unit box for none)."""
    if bounds is not None:
        lo, hi = bounds
    else:
        lo, hi = point_bounds(tri_verts.reshape(-1, 3), n_chunks) if len(tri_verts) else _finite_bounds(tri_verts)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        lo, hi = _finite_bounds(tri_verts)
    if not np.all(np.isfinite(lo)):            # empty scene: a unit box, no triangles
        lo, hi = np.zeros(3, np.float32), np.ones(3, np.float32)
    return lo, hi


def bin_triangles(tri_verts, shape: GridShape, n_chunks: int):
    """(cell_start, cell_tris) of tri_verts (n, 9) in the cells of `shape`."""
    n_chunks = max(1, min(n_chunks, max(len(tri_verts), 1)))
    return _fill(tri_verts, shape.lo, shape.inv_cell, shape.dims, shape.pad, n_chunks)


def build_grid(tri_verts: np.ndarray, density: float = 0.25, n_chunks: int = 0,
               bounds=None) -> Grid:
    """Build the grid over tri_verts (n, 9) f32. `n_chunks` 0 = one per thread.
    `bounds` (lo, hi): a box around every triangle, e.g. point_bounds of the
    mesh vertices (cheaper than reading all triangle corners)."""
    import numba
    if n_chunks <= 0:
        n_chunks = numba.get_num_threads()
    lo, hi = finite_bounds(tri_verts, bounds, max(1, min(n_chunks, max(len(tri_verts), 1))))
    shape = grid_shape(lo, hi, tri_verts.shape[0], density)
    cell_start, cell_tris = bin_triangles(tri_verts, shape, n_chunks)
    return Grid(shape.lo, shape.hi, shape.dims, shape.cell_size, shape.inv_cell, cell_start, cell_tris)


@parallel_arith_kernel
def merge_cells(a_start, a_tris, b_start, b_tris, b_ids, out_start, out_tris):
    """Per cell: the triangles of list a, then those of list b mapped through
    b_ids (local -> scene triangle id). out_start = a_start + b_start."""
    n_cells = a_start.shape[0] - 1
    for c in prange(n_cells + 1):
        out_start[c] = a_start[c] + b_start[c]
    for c in prange(n_cells):
        o = out_start[c]
        a0 = a_start[c]
        na = a_start[c + 1] - a0
        for i in range(na):
            out_tris[o + i] = a_tris[a0 + i]
        o += na
        b0 = b_start[c]
        for i in range(b_start[c + 1] - b0):
            out_tris[o + i] = b_ids[b_tris[b0 + i]]
