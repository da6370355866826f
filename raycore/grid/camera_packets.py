"""Camera packets: the rays of an NxN block of pixels, set up from their
corner rays (MLRTA, Reshetov et al. 2005) for the grid walk, or written out
ray by ray for the single-ray fallback."""
import numpy as np

from raycore.jit.presets import helper
from raycore.geometry.camera import primary_dir
from raycore.grid.cgt import (DK, DU, DV, DX, DY, DZ, OK, OU, OV, OX, OY, OZ, SU, SV, SZ, TEXIT,
                             TMAX, TMIN, WTMIN, packet_bounds, pick_axis, set_bounds)
from raycore.grid.packet_layout import sub_corner
from raycore.jit.floats import F0, F1, INF


@helper
def camera_rays(rays, cam, px, py, packet, sub_size, width, height, jx, jy, off_x, off_y):
    """The packet's camera rays as general rays (for the DDA fallback)."""
    for j in range(rays.shape[1]):
        x0, y0 = sub_corner(px, py, j, packet, sub_size)
        for r in range(rays.shape[2]):
            x = x0 + off_x[r]
            y = y0 + off_y[r]
            dx, dy, dz = primary_dir(cam, x, y, jx, jy)
            rays[OX, j, r] = cam[0]
            rays[OY, j, r] = cam[1]
            rays[OZ, j, r] = cam[2]
            rays[DX, j, r] = dx
            rays[DY, j, r] = dy
            rays[DZ, j, r] = dz
            rays[TMIN, j, r] = F0
            rays[TMAX, j, r] = INF if (x < width) & (y < height) else -F1


@helper
def setup_camera(cam, px, py, packet, sub_size, width, height, jx, jy, off_x, off_y,
                 work, hit_t, hit_prim, sub, sub_active, g_lo, g_hi, eps):
    """Corner-ray set-up of a camera packet (MLRTA-style, Reshetov et al. 2005).

    All rays leave the eye and their unnormalised directions are affine in
    the pixel position, so each direction component, and each slope d_u/d_k,
    takes its extremes at the corner rays of a (sub-)packet: the major axis
    and the frustum bounds come from 4 rays instead of all of them. Rays start
    at the eye, so the packet's entry plane is the eye's K coordinate clamped
    into the grid. Returns (K, s, n_live, k_ref, w_end) like setup_rays."""
    n_sub = work.shape[1]
    ss = work.shape[2]
    for j in range(n_sub):
        for r in range(ss):
            hit_t[j, r] = INF
            hit_prim[j, r] = -1
    # major axis from the 4 corner rays of the whole packet
    mn0 = mn1 = mn2 = INF
    mx0 = mx1 = mx2 = -INF
    for c in range(4):
        dx, dy, dz = primary_dir(cam, px + (packet - 1) * (c & 1), py + (packet - 1) * (c >> 1), jx, jy)
        mn0, mn1, mn2 = min(mn0, dx), min(mn1, dy), min(mn2, dz)
        mx0, mx1, mx2 = max(mx0, dx), max(mx1, dy), max(mx2, dz)
    K, s = pick_axis(mn0, mn1, mn2, mx0, mx1, mx2)
    if K < 0:
        return K, s, 0, F0, F0
    U = (K + 1) % 3
    V = (K + 2) % 3
    sf = np.float32(s)
    ok = cam[K]
    ou = cam[U]
    ov = cam[V]
    if s > 0:
        k_ref = max(ok, g_lo[K])
        w_end = g_hi[K] - k_ref
    else:
        k_ref = min(ok, g_hi[K])
        w_end = k_ref - g_lo[K]
    if not w_end >= F0:                # the eye is past the grid along K
        return K, s, 0, F0, F0
    ex, ey, ez = cam[0], cam[1], cam[2]
    f0, f1, f2 = cam[3], cam[4], cam[5]
    r0, r1, r2 = cam[6], cam[7], cam[8]
    q0, q1, q2 = cam[9], cam[10], cam[11]
    c12, c13, c14, c15 = cam[12], cam[13], cam[14], cam[15]
    lo_x, lo_y, lo_z = g_lo[0], g_lo[1], g_lo[2]
    hi_x, hi_y, hi_z = g_hi[0], g_hi[1], g_hi[2]
    n_live = 0
    for j in range(n_sub):
        x0, y0 = sub_corner(px, py, j, packet, sub_size)
        u0 = v0 = gu0 = gv0 = INF
        u1 = v1 = gu1 = gv1 = -INF
        for c in range(4):
            dx, dy, dz = primary_dir(cam, x0 + (sub_size - 1) * (c & 1),
                                     y0 + (sub_size - 1) * (c >> 1), jx, jy)
            d = (dx, dy, dz)
            dk = d[K]
            su = d[U] / dk
            sv = d[V] / dk
            u = ou + (k_ref - ok) * su
            v = ov + (k_ref - ok) * sv
            u0, u1 = min(u0, u), max(u1, u)
            v0, v1 = min(v0, v), max(v1, v)
            gu0, gu1 = min(gu0, su * sf), max(gu1, su * sf)
            gv0, gv1 = min(gv0, sv * sf), max(gv1, sv * sf)
        set_bounds(sub, j, u0, u1, gu0, gu1, v0, v1, gv0, gv1, eps)
        live = 0
        # per-ray loop over scalars only (no loads of cam/grid inside), so that
        # LLVM needs no alias checks and vectorizes it
        for r in range(ss):
            x = x0 + off_x[r]
            y = y0 + off_y[r]
            cu = (np.float32(x) + jx) * c14 - c12
            cv = c13 - (np.float32(y) + jy) * c15
            dx = f0 + cu * r0 + cv * q0
            dy = f1 + cu * r1 + cv * q1
            dz = f2 + cu * r2 + cv * q2
            inv = F1 / np.sqrt(dx * dx + dy * dy + dz * dz)
            dx *= inv
            dy *= inv
            dz *= inv
            # permutation by selects on loop-invariant axes (exact, vectorizes)
            dk = dx if K == 0 else (dy if K == 1 else dz)
            du = dx if U == 0 else (dy if U == 1 else dz)
            dv = dx if V == 0 else (dy if V == 1 else dz)
            sz = F1 / dk
            work[OU, j, r] = ou
            work[OV, j, r] = ov
            work[OK, j, r] = ok
            work[SU, j, r] = du * sz
            work[SV, j, r] = dv * sz
            work[DU, j, r] = du
            work[DV, j, r] = dv
            work[SZ, j, r] = sz
            work[DK, j, r] = dk
            work[WTMIN, j, r] = F0
            ix = F1 / dx
            iy = F1 / dy
            iz = F1 / dz
            xa = (lo_x - ex) * ix
            xb = (hi_x - ex) * ix
            ya = (lo_y - ey) * iy
            yb = (hi_y - ey) * iy
            za = (lo_z - ez) * iz
            zb = (hi_z - ez) * iz
            t0 = max(max(F0, min(xa, xb)), max(min(ya, yb), min(za, zb)))
            t1 = min(min(max(xa, xb), max(ya, yb)), max(za, zb))
            on = (x < width) & (y < height) & (t0 <= t1)
            work[TEXIT, j, r] = t1 if on else -INF
            live += 1 if on else 0
        sub_active[j] = live
        n_live += live
    packet_bounds(sub, sub_active)
    return K, s, n_live, k_ref, w_end
