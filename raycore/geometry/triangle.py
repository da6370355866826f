"""Watertight ray/triangle intersection (Woop, Benthin, Wald, JCGT 2013).

The ray is sheared so that it runs along +z through the origin; the triangle's
2D edge functions U, V, W then decide the hit. Each vertex is transformed the
same way for every triangle that shares it, and each edge function of a shared
edge is computed as the exact negative of its neighbour's (no FMA contraction:
see `jit/presets.py`), so a ray can never slip between two triangles. Zero edge values
count as hits (inclusive), so rays through a shared edge or vertex hit at least
one of its triangles.

Stages, cheapest early exit first: edge signs -> determinant -> one deferred
divide for t. The caller chooses the shear axis `kz` (any axis where the ray's
direction is non-zero keeps the test watertight; the largest component keeps
it accurate). Inputs are already permuted so that index 2 is `kz`.
"""
import numpy as np

from raycore.jit.presets import helper, kernel


@kernel
def ray_axes(dx, dy, dz):
    """Permutation (kx, ky, kz) with kz the largest |direction| component."""
    ax, ay, az = abs(dx), abs(dy), abs(dz)
    if ax >= ay and ax >= az:
        kz = 0
    elif ay >= az:
        kz = 1
    else:
        kz = 2
    kx = (kz + 1) % 3
    ky = (kx + 1) % 3
    return kx, ky, kz


ZERO = np.float32(0.0)
ONE = np.float32(1.0)


@kernel
def woop_test(ax, ay, az, bx, by, bz, cx, cy, cz, sx, sy, sz):
    """Edge functions and scaled distance for one ray and one triangle.

    a*, b*, c*: vertices minus the ray origin, permuted (x=kx, y=ky, z=kz).
    sx = d[kx]/d[kz], sy = d[ky]/d[kz], sz = 1/d[kz].
    Returns (hit, t, b1, b2): b1, b2 are the barycentric weights of b and c.
    Branch-free (bitwise logic, float32 constants) so that a loop over rays
    calling it vectorizes.
    """
    # shear the vertices onto the ray's 2D plane
    Ax = ax - sx * az
    Ay = ay - sy * az
    Bx = bx - sx * bz
    By = by - sy * bz
    Cx = cx - sx * cz
    Cy = cy - sy * cz
    # edge functions (antisymmetric for a shared edge)
    U = Cx * By - Cy * Bx
    V = Ax * Cy - Ay * Cx
    W = Bx * Ay - By * Ax
    outside = ((U < ZERO) | (V < ZERO) | (W < ZERO)) & ((U > ZERO) | (V > ZERO) | (W > ZERO))
    det = U + V + W
    # one deferred divide: t = sz * (U az + V bz + W cz) / det
    T = sz * (U * az + V * bz + W * cz)
    inv_det = ONE / det
    hit = (not outside) & (det != ZERO)
    return hit, T * inv_det, V * inv_det, W * inv_det


@helper
def sheared_test(tri_verts, tri, o, kx, ky, kz, sx, sy, sz):
    """woop_test of triangle `tri` for a ray from o (tuple) with shear
    (kx, ky, kz, sx, sy, sz) already set up: (hit, t, b1, b2)."""
    return woop_test(
        tri_verts[tri, kx] - o[kx], tri_verts[tri, ky] - o[ky], tri_verts[tri, kz] - o[kz],
        tri_verts[tri, 3 + kx] - o[kx], tri_verts[tri, 3 + ky] - o[ky], tri_verts[tri, 3 + kz] - o[kz],
        tri_verts[tri, 6 + kx] - o[kx], tri_verts[tri, 6 + ky] - o[ky], tri_verts[tri, 6 + kz] - o[kz],
        sx, sy, sz)


@helper
def intersect_ray(ox, oy, oz, dx, dy, dz, tri_verts, tri, t_min, t_max):
    """Closest-hit test of one ray against triangle `tri` of tri_verts (n, 9).

    Shear axis = largest direction component. Returns (hit, t, b1, b2) with
    hit only when t_min < t < t_max.
    """
    kx, ky, kz = ray_axes(dx, dy, dz)
    d = (dx, dy, dz)
    sz = ONE / d[kz]
    hit, t, b1, b2 = sheared_test(tri_verts, tri, (ox, oy, oz), kx, ky, kz, d[kx] * sz, d[ky] * sz, sz)
    hit = hit & (t > t_min) & (t < t_max)
    return hit, t, b1, b2


@helper
def surface_point(tri_verts, tri, b1, b2):
    """Hit point from barycentrics (more accurate than o + t d) and the unit
    geometric normal of triangle `tri`: (px, py, pz, nx, ny, nz)."""
    b0 = ONE - b1 - b2
    px = b0 * tri_verts[tri, 0] + b1 * tri_verts[tri, 3] + b2 * tri_verts[tri, 6]
    py = b0 * tri_verts[tri, 1] + b1 * tri_verts[tri, 4] + b2 * tri_verts[tri, 7]
    pz = b0 * tri_verts[tri, 2] + b1 * tri_verts[tri, 5] + b2 * tri_verts[tri, 8]
    e1x = tri_verts[tri, 3] - tri_verts[tri, 0]
    e1y = tri_verts[tri, 4] - tri_verts[tri, 1]
    e1z = tri_verts[tri, 5] - tri_verts[tri, 2]
    e2x = tri_verts[tri, 6] - tri_verts[tri, 0]
    e2y = tri_verts[tri, 7] - tri_verts[tri, 1]
    e2z = tri_verts[tri, 8] - tri_verts[tri, 2]
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    length = np.sqrt(nx * nx + ny * ny + nz * nz)
    inv = ONE / length if length > ZERO else ZERO
    return px, py, pz, nx * inv, ny * inv, nz * inv
