"""Grid build: every triangle is listed in every cell its box overlaps."""
import numpy as np

from conftest import soup
from raycore.grid.build import build_grid, grid_dims


def brute_cells(grid, tv):
    """Set of (cell, tri) from a slow per-triangle listing over the bboxes."""
    nx, ny, nz = grid.dims
    out = set()
    for t in range(len(tv)):
        p = tv[t].reshape(3, 3)
        lo = np.floor((p.min(0) - grid.lo) / grid.cell_size).astype(int)
        hi = np.floor((p.max(0) - grid.lo) / grid.cell_size).astype(int)
        lo = np.clip(lo, 0, grid.dims - 1)
        hi = np.clip(hi, 0, grid.dims - 1)
        for z in range(lo[2], hi[2] + 1):
            for y in range(lo[1], hi[1] + 1):
                for x in range(lo[0], hi[0] + 1):
                    out.add(((z * ny + y) * nx + x, t))
    return out


def listed(grid):
    out = set()
    for c in range(len(grid.cell_start) - 1):
        for j in range(grid.cell_start[c], grid.cell_start[c + 1]):
            out.add((c, int(grid.cell_tris[j])))
    return out


def test_every_overlapped_cell_lists_the_triangle(rng):
    tv = soup(rng, 400)
    grid = build_grid(tv, n_chunks=3)
    got = listed(grid)
    assert brute_cells(grid, tv) <= got
    # the widening pad adds at most a neighbour cell, never a far one
    assert len(got) <= 1.5 * len(brute_cells(grid, tv))


def test_cells_list_triangles_in_ascending_order_whatever_the_chunking(rng):
    tv = soup(rng, 500)
    a, b = build_grid(tv, n_chunks=1), build_grid(tv, n_chunks=7)
    assert np.array_equal(a.cell_start, b.cell_start) and np.array_equal(a.cell_tris, b.cell_tris)
    for c in range(len(a.cell_start) - 1):
        seg = a.cell_tris[a.cell_start[c]:a.cell_start[c + 1]]
        assert np.all(np.diff(seg) > 0)


def test_density_sets_cell_count_and_flat_scenes_keep_resolution():
    assert abs(np.prod(grid_dims(np.array([1.0, 1, 1]), 10000, 1.0)) - 10000) < 1500
    flat = grid_dims(np.array([10.0, 0.0, 10.0]), 10000, 1.0)
    assert flat[1] == 1 and flat[0] * flat[2] > 5000


def test_non_finite_triangles_are_left_out(rng):
    tv = soup(rng, 50)
    tv[3, 4] = np.nan
    tv[7, 0] = np.inf
    grid = build_grid(tv)
    assert np.all(np.isfinite(grid.lo)) and np.all(np.isfinite(grid.hi))
    ids = set(grid.cell_tris.tolist())
    assert 3 not in ids and 7 not in ids and len(ids) == 48


def test_bounds_from_vertices_give_the_same_grid(rng):
    from raycore.grid.build import point_bounds
    vertices = (rng.random((300, 3)) * 4 - 2).astype(np.float32)
    faces = rng.integers(0, 300, size=(500, 3)).astype(np.int32)
    tv = np.ascontiguousarray(vertices[faces].reshape(-1, 9))
    used = np.unique(faces)
    a = build_grid(tv)
    b = build_grid(tv, bounds=point_bounds(vertices[used], 2))
    assert np.array_equal(a.lo, b.lo) and np.array_equal(a.cell_tris, b.cell_tris)
    c = build_grid(tv, bounds=point_bounds(vertices, 2))        # unused vertices only widen it
    assert np.all(c.lo <= a.lo) and np.all(c.hi >= a.hi)
