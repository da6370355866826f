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

Ray packets are SoA rows of float32 arrays; ray r of sub-packet j sits at
index j*S*S + r so that each sub-packet loop runs from 0 with a fixed count.
"""
import numpy as np

from ._jit import kernel
from .triangle import woop_test

# rows of the `rays` input array (8, P)
OX, OY, OZ, DX, DY, DZ, TMIN, TMAX = 0, 1, 2, 3, 4, 5, 6, 7
# rows of the `work` scratch array (8, P): permuted origin, shear, exit
OU, OV, OK, SU, SV, SZ, DK, TEXIT = 0, 1, 2, 3, 4, 5, 6, 7
# rows of the `sub` scratch array (8, n_sub): sub-packet frustum bounds
UMIN, UMAX, GUMIN, GUMAX, VMIN, VMAX, GVMIN, GVMAX = 0, 1, 2, 3, 4, 5, 6, 7
MAILBOX_SIZE = 256            # power of two; collisions only cost a re-test
# counters (per tile): 0 packets, 1 cells visited, 2 ray-triangle tests,
# 3 triangle candidates after mailbox, 4 rays sent to the single-ray fallback
N_COUNTERS = 5


@kernel
def choose_major_axis(rays, n_rays):
    """Axis on which every active ray has the same non-zero direction sign,
    preferring the largest minimum |d|. Returns (axis, sign, n_active); axis
    -1 when no axis qualifies (caller falls back to single rays)."""
    best = -1
    best_val = np.float32(0.0)
    best_sign = 0
    n_active = 0
    for i in range(n_rays):
        if rays[TMAX, i] > rays[TMIN, i]:
            n_active += 1
    if n_active == 0:
        return -1, 0, 0
    for a in range(3):
        mn = np.float32(np.inf)
        mx = np.float32(-np.inf)
        for i in range(n_rays):
            if rays[TMAX, i] > rays[TMIN, i]:
                d = rays[DX + a, i]
                mn = min(mn, d)
                mx = max(mx, d)
        if mn > 0.0 and mn > best_val:
            best, best_val, best_sign = a, mn, 1
        elif mx < 0.0 and -mx > best_val:
            best, best_val, best_sign = a, -mx, -1
    return best, best_sign, n_active


@kernel
def cgt_packet(rays, work, hit_t, hit_b1, hit_b2, hit_prim, n_rays, sub_size,
               any_hit, sub, sub_active, sub_done, mailbox,
               g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris,
               tri_verts, eps, counters, tile):
    """Trace one packet. Fills hit_t/hit_prim/hit_b1/hit_b2 for its rays
    (prim -1 = no hit before TMAX) and returns True, or returns False without
    touching the hits when the rays share no major axis."""
    K, s, n_active = choose_major_axis(rays, n_rays)
    for i in range(n_rays):
        hit_t[i] = rays[TMAX, i]
        hit_prim[i] = -1
    if n_active == 0:
        return True
    if K < 0:
        return False
    U = (K + 1) % 3
    V = (K + 2) % 3
    ss = sub_size * sub_size
    n_sub = n_rays // ss
    counters[tile, 0] += 1

    # --- per ray: permuted origin, Woop shear, clip to the grid -------------
    lo_k = g_lo[K]
    k_first = np.float32(np.inf)
    k_last = np.float32(-np.inf)
    for i in range(n_rays):
        o = (rays[OX, i], rays[OY, i], rays[OZ, i])
        d = (rays[DX, i], rays[DY, i], rays[DZ, i])
        dk = d[K]
        sz = np.float32(1.0) / dk
        work[OU, i] = o[U]
        work[OV, i] = o[V]
        work[OK, i] = o[K]
        work[SU, i] = d[U] * sz
        work[SV, i] = d[V] * sz
        work[SZ, i] = sz
        work[DK, i] = dk
        t0 = rays[TMIN, i]
        t1 = rays[TMAX, i]
        if t1 > t0:
            for a in range(3):
                if d[a] != 0.0:
                    ta = (g_lo[a] - o[a]) / d[a]
                    tb = (g_hi[a] - o[a]) / d[a]
                    t0 = max(t0, min(ta, tb))
                    t1 = min(t1, max(ta, tb))
                elif o[a] < g_lo[a] or o[a] > g_hi[a]:
                    t1 = np.float32(-np.inf)
        if t0 <= t1:
            work[TEXIT, i] = t1
            k0 = o[K] + t0 * dk
            k1 = o[K] + t1 * dk
            k_first = min(k_first, k0 * s) 
            k_last = max(k_last, k1 * s)
        else:
            work[TEXIT, i] = np.float32(-np.inf)
    if k_first > k_last:               # no ray enters the grid
        return True
    k_ref = k_first * s                # entry plane of the packet (w = 0)
    w_end = k_last - k_first           # farthest exit, in w

    # --- frustum bounds of the whole packet and of each sub-packet ----------
    pu0 = np.float32(np.inf)
    pu1 = np.float32(-np.inf)
    pgu0 = np.float32(np.inf)
    pgu1 = np.float32(-np.inf)
    pv0 = np.float32(np.inf)
    pv1 = np.float32(-np.inf)
    pgv0 = np.float32(np.inf)
    pgv1 = np.float32(-np.inf)
    n_live = 0
    for j in range(n_sub):
        u0 = np.float32(np.inf)
        u1 = np.float32(-np.inf)
        gu0 = np.float32(np.inf)
        gu1 = np.float32(-np.inf)
        v0 = np.float32(np.inf)
        v1 = np.float32(-np.inf)
        gv0 = np.float32(np.inf)
        gv1 = np.float32(-np.inf)
        live = 0
        for r in range(j * ss, (j + 1) * ss):
            if work[TEXIT, r] >= rays[TMIN, r] and rays[TMAX, r] > rays[TMIN, r]:
                live += 1
                dk_ref = k_ref - work[OK, r]
                u = work[OU, r] + dk_ref * work[SU, r]
                v = work[OV, r] + dk_ref * work[SV, r]
                gu = work[SU, r] * s
                gv = work[SV, r] * s
                u0 = min(u0, u)
                u1 = max(u1, u)
                v0 = min(v0, v)
                v1 = max(v1, v)
                gu0 = min(gu0, gu)
                gu1 = max(gu1, gu)
                gv0 = min(gv0, gv)
                gv1 = max(gv1, gv)
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
            w0 = max(np.float32(0.0), k_lo - k_ref)
            w1 = min(w_end, k_hi - k_ref)
        else:
            w0 = max(np.float32(0.0), k_ref - k_hi)
            w1 = min(w_end, k_ref - k_lo)
        # overlap box of this slice (frustum bounds at both ends)
        ulo = pu0 + min(w0 * pgu0, w1 * pgu0)
        uhi = pu1 + max(w0 * pgu1, w1 * pgu1)
        vlo = pv0 + min(w0 * pgv0, w1 * pgv0)
        vhi = pv1 + max(w0 * pgv1, w1 * pgv1)
        fu0 = (ulo - g_lo[U]) * g_inv[U]
        fu1 = (uhi - g_lo[U]) * g_inv[U]
        fv0 = (vlo - g_lo[V]) * g_inv[V]
        fv1 = (vhi - g_lo[V]) * g_inv[V]
        if fu1 >= 0.0 and fu0 < nU and fv1 >= 0.0 and fv0 < nV:
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
                        if (au - pgu0 * wa < pu0 and bu - pgu0 * wb < pu0
                                and cu - pgu0 * wc < pu0):
                            continue
                        if (au - pgu1 * wa > pu1 and bu - pgu1 * wb > pu1
                                and cu - pgu1 * wc > pu1):
                            continue
                        if (av - pgv0 * wa < pv0 and bv - pgv0 * wb < pv0
                                and cv - pgv0 * wc < pv0):
                            continue
                        if (av - pgv1 * wa > pv1 and bv - pgv1 * wb > pv1
                                and cv - pgv1 * wc > pv1):
                            continue
                        counters[tile, 3] += 1
                        for j in range(n_sub):
                            if sub_done[j] >= sub_active[j]:
                                continue
                            s_u0 = sub[UMIN, j]
                            s_gu0 = sub[GUMIN, j]
                            if (au - s_gu0 * wa < s_u0 and bu - s_gu0 * wb < s_u0
                                    and cu - s_gu0 * wc < s_u0):
                                continue
                            s_u1 = sub[UMAX, j]
                            s_gu1 = sub[GUMAX, j]
                            if (au - s_gu1 * wa > s_u1 and bu - s_gu1 * wb > s_u1
                                    and cu - s_gu1 * wc > s_u1):
                                continue
                            s_v0 = sub[VMIN, j]
                            s_gv0 = sub[GVMIN, j]
                            if (av - s_gv0 * wa < s_v0 and bv - s_gv0 * wb < s_v0
                                    and cv - s_gv0 * wc < s_v0):
                                continue
                            s_v1 = sub[VMAX, j]
                            s_gv1 = sub[GVMAX, j]
                            if (av - s_gv1 * wa > s_v1 and bv - s_gv1 * wb > s_v1
                                    and cv - s_gv1 * wc > s_v1):
                                continue
                            counters[tile, 2] += ss
                            base = j * ss
                            # branch-free ray loop: vectorized across the sub-packet
                            for r in range(ss):
                                i = base + r
                                ou = work[OU, i]
                                ov = work[OV, i]
                                ok = work[OK, i]
                                hit, t, b1, b2 = woop_test(
                                    au - ou, av - ov, ak - ok,
                                    bu - ou, bv - ov, bk - ok,
                                    cu - ou, cv - ov, ck - ok,
                                    work[SU, i], work[SV, i], work[SZ, i])
                                better = hit and t > rays[TMIN, i] and t < hit_t[i]
                                hit_t[i] = t if better else hit_t[i]
                                hit_b1[i] = b1 if better else hit_b1[i]
                                hit_b2[i] = b2 if better else hit_b2[i]
                                hit_prim[i] = tri if better else hit_prim[i]
        # --- stop once every ray is finished before the end of this slice ----
        done = 0
        for j in range(n_sub):
            dj = 0
            for r in range(j * ss, (j + 1) * ss):
                t_far = min(hit_t[r], work[TEXIT, r])
                w_far = (work[OK, r] + t_far * work[DK, r] - k_ref) * s
                fin = w_far <= w1 or (any_hit and hit_prim[r] >= 0)
                live = work[TEXIT, r] >= rays[TMIN, r] and rays[TMAX, r] > rays[TMIN, r]
                dj += 1 if (fin and live) else 0
            sub_done[j] = dj
            done += dj
        if done >= n_live:
            break
        q += s
    return True
