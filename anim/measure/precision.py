"""`bench --error`, the precision part: where float32 stops being enough.

One frame of a scene is scaled by s (1e-4 .. 1e4) and moved by an offset
(0 .. 1e6), camera with it, and its camera rays are traced by the float32
grid kernels and by a float64 brute-force reference over all triangles.
Reported per (scale, offset): the hit distance's relative error (median and
99th percentile, scale-free since t scales with s) and the share of pixels
whose hit or miss differs. float32 carries 24 bits: once the offset is
~1e6 / 2^24 ≈ 0.06 of the scene's own size, positions snap to a coarse
lattice and the image breaks up; the offsets in the code (shadow-ray
origins by ulps of magnitude, cull margins by grid extent) are relative for
that reason.
"""
import numpy as np
from numba import njit, prange

from raycore.accelerators import GridAccel
from raycore.geometry.camera import camera_basis, pixel_centre_rays
from raycore.grid.build import build_grid

SCALES = (1e-4, 1e-2, 1.0, 1e2, 1e4)
OFFSETS = (0.0, 1e2, 1e4, 1e6)
RES = 64


@njit(parallel=True, cache=True)
def brute_force_f64(origins, dirs, tris):
    """Closest hit distance (inf on a miss) of every ray against every
    triangle, Moller-Trumbore in float64 (the reference, not a kernel)."""
    n = origins.shape[0]
    out = np.full(n, np.inf)
    for i in prange(n):
        best = np.inf
        ox, oy, oz = origins[i, 0], origins[i, 1], origins[i, 2]
        dx, dy, dz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        for k in range(tris.shape[0]):
            ax, ay, az = tris[k, 0], tris[k, 1], tris[k, 2]
            e1x, e1y, e1z = tris[k, 3] - ax, tris[k, 4] - ay, tris[k, 5] - az
            e2x, e2y, e2z = tris[k, 6] - ax, tris[k, 7] - ay, tris[k, 8] - az
            px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
            det = e1x * px + e1y * py + e1z * pz
            if det == 0.0:
                continue
            inv = 1.0 / det
            tx, ty, tz = ox - ax, oy - ay, oz - az
            u = (tx * px + ty * py + tz * pz) * inv
            if u < 0.0 or u > 1.0:
                continue
            qx, qy, qz = ty * e1z - tz * e1y, tz * e1x - tx * e1z, tx * e1y - ty * e1x
            v = (dx * qx + dy * qy + dz * qz) * inv
            if v < 0.0 or u + v > 1.0:
                continue
            t = (e2x * qx + e2y * qy + e2z * qz) * inv
            if 0.0 < t < best:
                best = t
        out[i] = best
    return out


def precision_study(tri_verts64, pose, res=RES, scales=SCALES, offsets=OFFSETS):
    """Rows {scale, offset, median_rel, p99_rel, hit_mismatch} for one frame
    (tri_verts64 (n, 9) float64, pose = (eye, look_at, up, fov))."""
    eye, look_at, up, fov = (np.asarray(v, np.float64) if i < 3 else v for i, v in enumerate(pose))
    rows = []
    for scale in scales:
        for offset in offsets:
            tv = tri_verts64 * scale + offset
            e, la = eye * scale + offset, look_at * scale + offset
            basis = camera_basis(e, la, up, fov, res, res)              # float32, as the renderer has it
            grid = GridAccel(build_grid(np.ascontiguousarray(tv, np.float32)),
                             np.ascontiguousarray(tv, np.float32), 8)
            hits, (row_off, col_off) = grid.trace_camera(basis, res, res, (0.5, 0.5))
            idx = (row_off[:, None] + col_off[None, :]).reshape(-1)
            t32 = np.where(hits.prim[idx] >= 0, hits.t[idx], np.inf).astype(np.float64)
            o, d = pixel_centre_rays(camera_basis(e, la, up, fov, res, res, np.float64), res, res)
            t64 = brute_force_f64(o, d, tv)
            both = np.isfinite(t32) & np.isfinite(t64)
            rel = np.abs(t32[both] - t64[both]) / t64[both]
            # no pixel hit by both: nothing to compare (the float32 scene has collapsed)
            rows.append({"scale": scale, "offset": offset,
                         "median_rel": float(np.median(rel)) if both.any() else None,
                         "p99_rel": float(np.percentile(rel, 99)) if both.any() else None,
                         "hit_mismatch": float(np.mean(np.isfinite(t32) != np.isfinite(t64)))})
    return rows
