"""Single-ray 3D-DDA through the uniform grid (Amanatides & Woo 1987).

The reference traversal: packets fall back to it when their rays do not share
a major direction, and tests compare packets against it. DDA state lives in
scalars; a zero direction component never steps (its next crossing is +inf),
so 1/0 never turns into a NaN comparison.
"""
import numpy as np

from raycore.jit.presets import kernel
from raycore.geometry.triangle import ray_axes, sheared_test


@kernel
def clip_to_box(o, d, lo, hi, t0, t1):
    """Parametric range [t0, t1] of the ray inside the box; t0 > t1 = outside."""
    for a in range(3):
        if d[a] != 0.0:
            ta = (lo[a] - o[a]) / d[a]
            tb = (hi[a] - o[a]) / d[a]
            t0 = max(t0, min(ta, tb))
            t1 = min(t1, max(ta, tb))
        elif o[a] < lo[a] or o[a] > hi[a]:
            return t0, np.float32(-np.inf)
    return t0, t1


@kernel
def dda_trace(ox, oy, oz, dx, dy, dz, t_min, t_max, any_hit, grid, tri_verts):
    """Closest (or, with any_hit, any) hit in (t_min, t_max) in `grid`
    (grid/build.Grid).

    Returns (t, prim, b1, b2, cells_visited, tri_tests); prim = -1 on a miss.
    """
    g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris = grid
    o = (ox, oy, oz)
    d = (dx, dy, dz)
    best_t = t_max
    best_prim = -1
    best_b1 = np.float32(0.0)
    best_b2 = np.float32(0.0)
    t0, t1 = clip_to_box(o, d, g_lo, g_hi, t_min, t_max)
    if not (t0 <= t1) or dx == 0.0 and dy == 0.0 and dz == 0.0:
        return best_t, best_prim, best_b1, best_b2, 0, 0
    # Woop shear for this ray (largest axis), in float32 like the packets': a
    # float64 shear (1.0 / float32 is float64 in numba) loses watertightness,
    # and a ray through a shared vertex then missed all six triangles around it
    kx, ky, kz = ray_axes(dx, dy, dz)
    sz = np.float32(1.0) / d[kz]
    sx = d[kx] * sz
    sy = d[ky] * sz
    # DDA set-up at the entry point
    cell = np.empty(3, np.int64)
    step = np.empty(3, np.int64)
    t_next = np.empty(3, np.float32)
    t_delta = np.empty(3, np.float32)
    for a in range(3):
        p = o[a] + t0 * d[a]
        c = int(np.floor((p - g_lo[a]) * g_inv[a]))
        cell[a] = min(max(c, 0), g_dims[a] - 1)
        if d[a] > 0.0:
            step[a] = 1
            t_next[a] = (g_lo[a] + (cell[a] + 1) * g_cell[a] - o[a]) / d[a]
            t_delta[a] = g_cell[a] / d[a]
        elif d[a] < 0.0:
            step[a] = -1
            t_next[a] = (g_lo[a] + cell[a] * g_cell[a] - o[a]) / d[a]
            t_delta[a] = -g_cell[a] / d[a]
        else:
            step[a] = 0
            t_next[a] = np.inf
            t_delta[a] = np.inf
    nx = g_dims[0]
    ny = g_dims[1]
    visited = 0
    tests = 0
    while True:
        visited += 1
        idx = (cell[2] * ny + cell[1]) * nx + cell[0]
        for j in range(cell_start[idx], cell_start[idx + 1]):
            tri = cell_tris[j]
            tests += 1
            hit, t, b1, b2 = sheared_test(tri_verts, tri, o, kx, ky, kz, sx, sy, sz)
            if hit and t > t_min and t < best_t:
                best_t = t
                best_prim = tri
                best_b1 = b1
                best_b2 = b2
        if any_hit and best_prim >= 0:
            break
        # next cell: the axis whose boundary comes first
        a = 0
        if t_next[1] < t_next[a]:
            a = 1
        if t_next[2] < t_next[a]:
            a = 2
        # a hit before the next boundary cannot be beaten by later cells
        if best_t <= t_next[a] or t_next[a] > t1:
            break
        cell[a] += step[a]
        if cell[a] < 0 or cell[a] >= g_dims[a]:
            break
        t_next[a] += t_delta[a]
    return best_t, best_prim, best_b1, best_b2, visited, tests
