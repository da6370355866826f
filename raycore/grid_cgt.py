"""Coherent Grid Traversal of one NxN ray packet (Wald, Ize, Kensler, Knoll,
Parker 2006, "Ray Tracing Animated Scenes using Coherent Grid Traversal").

The packet walks the grid slice by slice along its major axis K (the axis on
which every ray's direction has the same non-zero sign). For every ray the two
other coordinates are affine in the distance w travelled along K from the
packet's entry plane: u(w) = u0 + w * gu. The bounds
    u >= min(u0) + w * min(gu),   u <= max(u0) + w * max(gu)   (same for v)
therefore hold for every ray at every w >= 0; they are the packet's frustum.
Per slice [w0, w1] they give the overlap box of cells, updated by two
multiply-adds per slice. Each candidate triangle is
  1. skipped if the mailbox says this packet has tested it already,
  2. culled against the packet frustum (all 3 vertices outside one plane),
  3. culled against each SxS sub-packet's own frustum (S = min(N, 8)),
  4. tested against the sub-packet's rays in one branch-free loop that LLVM
     vectorizes (watertight Woop test, shear axis = K for the whole packet).
The walk stops once every ray's closest hit (or exit) lies before the end of
the current slice. Works for any origins (primary rays share one; shadow rays
from surface points do not), since only the affine bounds are used.

Ray packets are SoA float32 arrays shaped (row, sub-packet j, ray r): every
loop indexes them with loop counters that start at 0, which lets LLVM drop
numba's negative-index wraparound and vectorize the per-ray loops (an index
like `base + r` instead measured 3-4x slower).
"""
import numpy as np

from ._jit import kernel
from .triangle import woop_test

F0 = np.float32(0.0)
F1 = np.float32(1.0)
INF = np.float32(np.inf)
# rows of the `rays` input array (8, n_sub, S*S)
OX, OY, OZ, DX, DY, DZ, TMIN, TMAX = 0, 1, 2, 3, 4, 5, 6, 7
# rows of the `work` scratch array (8, n_sub, S*S): permuted origin, shear, exit
OU, OV, OK, SU, SV, SZ, DK, TEXIT = 0, 1, 2, 3, 4, 5, 6, 7
# rows of the `sub` scratch array (8, n_sub): sub-packet frustum bounds
UMIN, UMAX, GUMIN, GUMAX, VMIN, VMAX, GVMIN, GVMAX = 0, 1, 2, 3, 4, 5, 6, 7
MAILBOX_SIZE = 256            # power of two; collisions only cost a re-test
# counters (per tile): 0 packets, 1 cells visited, 2 ray-triangle tests,
# 3 triangle candidates after mailbox, 4 rays sent to the single-ray fallback
N_COUNTERS = 5


@kernel
def choose_major_axis(rays):
    """Axis on which every active ray has the same non-zero direction sign,
    preferring the largest minimum |d|. Returns (axis, sign, n_active); axis
    -1 when no axis qualifies (caller falls back to single rays)."""
    n_sub = rays.shape[1]
    ss = rays.shape[2]
    n_active = 0
    mn0 = mn1 = mn2 = INF
    mx0 = mx1 = mx2 = -INF
    for j in range(n_sub):
        for r in range(ss):
            active = rays[TMAX, j, r] > rays[TMIN, j, r]
            n_active += 1 if active else 0
            d0 = rays[DX, j, r]
            d1 = rays[DY, j, r]
            d2 = rays[DZ, j, r]
            mn0 = min(mn0, d0 if active else INF)
            mn1 = min(mn1, d1 if active else INF)
            mn2 = min(mn2, d2 if active else INF)
            mx0 = max(mx0, d0 if active else -INF)
            mx1 = max(mx1, d1 if active else -INF)
            mx2 = max(mx2, d2 if active else -INF)
    if n_active == 0:
        return -1, 0, 0
    best = -1
    best_val = F0
    best_sign = 0
    mn = (mn0, mn1, mn2)
    mx = (mx0, mx1, mx2)
    for a in range(3):
        if mn[a] > F0 and mn[a] > best_val:
            best, best_val, best_sign = a, mn[a], 1
        elif mx[a] < F0 and -mx[a] > best_val:
            best, best_val, best_sign = a, -mx[a], -1
    return best, best_sign, n_active


@kernel
def _cull_plane(au, wa, bu, wb, cu, wc, g, bound, lower):
    """True when all three vertices lie outside the plane u - g*w = bound
    (below it for a lower bound, above it for an upper one)."""
    if lower:
        return (au - g * wa < bound) & (bu - g * wb < bound) & (cu - g * wc < bound)
    return (au - g * wa > bound) & (bu - g * wb > bound) & (cu - g * wc > bound)


@kernel
def cgt_packet(rays, work, hit_t, hit_b1, hit_b2, hit_prim, any_hit,
               sub, sub_active, sub_done, mailbox,
               g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris,
               tri_verts, eps, counters, tile):
    """Trace one packet. Fills hit_t/hit_prim/hit_b1/hit_b2 (n_sub, S*S) for
    its rays (prim -1 = no hit before TMAX) and returns True, or returns
    False when the rays share no major axis (hits then undefined)."""
    n_sub = rays.shape[1]
    ss = rays.shape[2]
    K, s, n_active = choose_major_axis(rays)
    for j in range(n_sub):
        for r in range(ss):
            hit_t[j, r] = rays[TMAX, j, r]
            hit_prim[j, r] = -1
    if n_active == 0:
        return True
    if K < 0:
        return False
    U = (K + 1) % 3
    V = (K + 2) % 3
    counters[tile, 0] += 1

    # --- per ray: permuted origin, Woop shear, clip to the grid -------------
    lo_k = g_lo[K]
    lo_x, lo_y, lo_z = g_lo[0], g_lo[1], g_lo[2]
    hi_x, hi_y, hi_z = g_hi[0], g_hi[1], g_hi[2]
    k_first = INF
    k_last = -INF
    for j in range(n_sub):
        for r in range(ss):
            dk = rays[DX + K, j, r]
            sz = F1 / dk
            ok = rays[OX + K, j, r]
            work[OU, j, r] = rays[OX + U, j, r]
            work[OV, j, r] = rays[OX + V, j, r]
            work[OK, j, r] = ok
            work[SU, j, r] = rays[DX + U, j, r] * sz
            work[SV, j, r] = rays[DX + V, j, r] * sz
            work[SZ, j, r] = sz
            work[DK, j, r] = dk
            # slab clip, branch-free: a zero direction gives +-inf bounds, and a
            # 0 * inf NaN (origin on a slab plane) loses every min/max below
            t0 = rays[TMIN, j, r]
            t1 = rays[TMAX, j, r]
            ix = F1 / rays[DX, j, r]
            iy = F1 / rays[DY, j, r]
            iz = F1 / rays[DZ, j, r]
            xa = (lo_x - rays[OX, j, r]) * ix
            xb = (hi_x - rays[OX, j, r]) * ix
            ya = (lo_y - rays[OY, j, r]) * iy
            yb = (hi_y - rays[OY, j, r]) * iy
            za = (lo_z - rays[OZ, j, r]) * iz
            zb = (hi_z - rays[OZ, j, r]) * iz
            t0 = max(t0, min(xa, xb))
            t1 = min(t1, max(xa, xb))
            t0 = max(t0, min(ya, yb))
            t1 = min(t1, max(ya, yb))
            t0 = max(t0, min(za, zb))
            t1 = min(t1, max(za, zb))
            inside = t0 <= t1
            work[TEXIT, j, r] = t1 if inside else -INF
            k_first = min(k_first, (ok + t0 * dk) * s if inside else INF)
            k_last = max(k_last, (ok + t1 * dk) * s if inside else -INF)
    if k_first > k_last:               # no ray enters the grid
        return True
    k_ref = k_first * s                # entry plane of the packet (w = 0)
    w_end = k_last - k_first           # farthest exit, in w

    # --- frustum bounds of the whole packet and of each sub-packet ----------
    pu0 = INF
    pu1 = -INF
    pgu0 = INF
    pgu1 = -INF
    pv0 = INF
    pv1 = -INF
    pgv0 = INF
    pgv1 = -INF
    n_live = 0
    for j in range(n_sub):
        u0 = INF
        u1 = -INF
        gu0 = INF
        gu1 = -INF
        v0 = INF
        v1 = -INF
        gv0 = INF
        gv1 = -INF
        live = 0
        for r in range(ss):
            on = (work[TEXIT, j, r] >= rays[TMIN, j, r]) & (rays[TMAX, j, r] > rays[TMIN, j, r])
            live += 1 if on else 0
            dk_ref = k_ref - work[OK, j, r]
            u = work[OU, j, r] + dk_ref * work[SU, j, r]
            v = work[OV, j, r] + dk_ref * work[SV, j, r]
            gu = work[SU, j, r] * s
            gv = work[SV, j, r] * s
            u0 = min(u0, u if on else INF)
            u1 = max(u1, u if on else -INF)
            v0 = min(v0, v if on else INF)
            v1 = max(v1, v if on else -INF)
            gu0 = min(gu0, gu if on else INF)
            gu1 = max(gu1, gu if on else -INF)
            gv0 = min(gv0, gv if on else INF)
            gv1 = max(gv1, gv if on else -INF)
        sub_active[j] = live
        sub_done[j] = 0
        sub[UMIN, j] = u0 - eps
        sub[UMAX, j] = u1 + eps
        sub[GUMIN, j] = gu0
        sub[GUMAX, j] = gu1
        sub[VMIN, j] = v0 - eps
        sub[VMAX, j] = v1 + eps
        sub[GVMIN, j] = gv0
        sub[GVMAX, j] = gv1
        n_live += live
        if live > 0:
            pu0 = min(pu0, u0)
            pu1 = max(pu1, u1)
            pv0 = min(pv0, v0)
            pv1 = max(pv1, v1)
            pgu0 = min(pgu0, gu0)
            pgu1 = max(pgu1, gu1)
            pgv0 = min(pgv0, gv0)
            pgv1 = max(pgv1, gv1)
    pu0 -= eps
    pu1 += eps
    pv0 -= eps
    pv1 += eps
    for m in range(MAILBOX_SIZE):
        mailbox[m] = -1

    # --- walk the slices along K ---------------------------------------------
    nK = g_dims[K]
    nU = g_dims[U]
    nV = g_dims[V]
    stride = (np.int64(1), np.int64(g_dims[0]), np.int64(g_dims[0]) * g_dims[1])
    sK = stride[K]
    sU = stride[U]
    sV = stride[V]
    q = min(max(int(np.floor((k_ref - lo_k) * g_inv[K])), 0), nK - 1)
    q_last = min(max(int(np.floor((k_last * s - lo_k) * g_inv[K])), 0), nK - 1)
    n_slices = (q_last - q) * s + 1
    for _ in range(n_slices):
        k_lo = lo_k + q * g_cell[K]
        k_hi = k_lo + g_cell[K]
        if s > 0:
            w0 = max(F0, k_lo - k_ref)
            w1 = min(w_end, k_hi - k_ref)
        else:
            w0 = max(F0, k_ref - k_hi)
            w1 = min(w_end, k_ref - k_lo)
        # overlap box of this slice (frustum bounds at both ends)
        fu0 = (pu0 + min(w0 * pgu0, w1 * pgu0) - g_lo[U]) * g_inv[U]
        fu1 = (pu1 + max(w0 * pgu1, w1 * pgu1) - g_lo[U]) * g_inv[U]
        fv0 = (pv0 + min(w0 * pgv0, w1 * pgv0) - g_lo[V]) * g_inv[V]
        fv1 = (pv1 + max(w0 * pgv1, w1 * pgv1) - g_lo[V]) * g_inv[V]
        if fu1 >= F0 and fu0 < nU and fv1 >= F0 and fv0 < nV:
            iu0 = max(int(np.floor(fu0)), 0)
            iu1 = min(int(np.floor(fu1)), nU - 1)
            iv0 = max(int(np.floor(fv0)), 0)
            iv1 = min(int(np.floor(fv1)), nV - 1)
            for iv in range(iv0, iv1 + 1):
                for iu in range(iu0, iu1 + 1):
                    cell = q * sK + iu * sU + iv * sV
                    counters[tile, 1] += 1
                    for jj in range(cell_start[cell], cell_start[cell + 1]):
                        tri = cell_tris[jj]
                        slot = tri & (MAILBOX_SIZE - 1)
                        if mailbox[slot] == tri:
                            continue
                        mailbox[slot] = tri
                        # triangle in the packet's frame: u, v, and w along K
                        au = tri_verts[tri, U]
                        av = tri_verts[tri, V]
                        ak = tri_verts[tri, K]
                        bu = tri_verts[tri, 3 + U]
                        bv = tri_verts[tri, 3 + V]
                        bk = tri_verts[tri, 3 + K]
                        cu = tri_verts[tri, 6 + U]
                        cv = tri_verts[tri, 6 + V]
                        ck = tri_verts[tri, 6 + K]
                        wa = (ak - k_ref) * s
                        wb = (bk - k_ref) * s
                        wc = (ck - k_ref) * s
                        if max(wa, wb, wc) < -eps or min(wa, wb, wc) > w_end + eps:
                            continue
                        # packet frustum: all vertices outside one plane -> cull
                        if (_cull_plane(au, wa, bu, wb, cu, wc, pgu0, pu0, True)
                                or _cull_plane(au, wa, bu, wb, cu, wc, pgu1, pu1, False)
                                or _cull_plane(av, wa, bv, wb, cv, wc, pgv0, pv0, True)
                                or _cull_plane(av, wa, bv, wb, cv, wc, pgv1, pv1, False)):
                            continue
                        counters[tile, 3] += 1
                        for j in range(n_sub):
                            if sub_done[j] >= sub_active[j]:
                                continue
                            if (_cull_plane(au, wa, bu, wb, cu, wc, sub[GUMIN, j], sub[UMIN, j], True)
                                    or _cull_plane(au, wa, bu, wb, cu, wc, sub[GUMAX, j], sub[UMAX, j], False)
                                    or _cull_plane(av, wa, bv, wb, cv, wc, sub[GVMIN, j], sub[VMIN, j], True)
                                    or _cull_plane(av, wa, bv, wb, cv, wc, sub[GVMAX, j], sub[VMAX, j], False)):
                                continue
                            counters[tile, 2] += ss
                            # branch-free ray loop: vectorized across the sub-packet
                            for r in range(ss):
                                ou = work[OU, j, r]
                                ov = work[OV, j, r]
                                ok = work[OK, j, r]
                                hit, t, b1, b2 = woop_test(
                                    au - ou, av - ov, ak - ok,
                                    bu - ou, bv - ov, bk - ok,
                                    cu - ou, cv - ov, ck - ok,
                                    work[SU, j, r], work[SV, j, r], work[SZ, j, r])
                                better = hit & (t > rays[TMIN, j, r]) & (t < hit_t[j, r])
                                hit_t[j, r] = t if better else hit_t[j, r]
                                hit_b1[j, r] = b1 if better else hit_b1[j, r]
                                hit_b2[j, r] = b2 if better else hit_b2[j, r]
                                hit_prim[j, r] = tri if better else hit_prim[j, r]
        # --- stop once every ray is finished before the end of this slice ----
        done = 0
        for j in range(n_sub):
            dj = 0
            for r in range(ss):
                t_far = min(hit_t[j, r], work[TEXIT, j, r])
                w_far = (work[OK, j, r] + t_far * work[DK, j, r] - k_ref) * s
                fin = (w_far <= w1) | (any_hit & (hit_prim[j, r] >= 0))
                live = (work[TEXIT, j, r] >= rays[TMIN, j, r]) & (rays[TMAX, j, r] > rays[TMIN, j, r])
                dj += 1 if (fin & live) else 0
            sub_done[j] = dj
            done += dj
        if done >= n_live:
            break
        q += s
    return True
