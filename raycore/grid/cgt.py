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

A packet is traced in two steps: a set-up fills the per-ray `work` rows and
the frustum bounds (`setup_rays` for rays with any origins, or the camera's
corner-ray set-up in grid/camera_packets.py), then `walk` traverses the grid.

Ray packets are SoA float32 arrays shaped (row, sub-packet j, ray r): every
loop indexes them with loop counters that start at 0, which lets LLVM drop
numba's negative-index wraparound and vectorize the per-ray loops (an index
like `base + r` instead measured 3-4x slower).

The file is longer than the others (~460 lines) for one reason: `walk` is
one kernel of ~190 lines whose slice, cell, triangle and ray loops share
their live values; its set-up and culling helpers read the same row
constants and make sense only beside it.
"""
import numpy as np

from raycore.jit.presets import helper, kernel
from raycore.jit.counters import CANDIDATES, PACKETS, TESTS, VISITS
from raycore.geometry.triangle import woop_test
from raycore.jit.floats import F0, F1, INF

# rows of the `rays` input array (8, n_sub, S*S)
OX, OY, OZ, DX, DY, DZ, TMIN, TMAX = 0, 1, 2, 3, 4, 5, 6, 7
# rows of the `work` array (11, n_sub, S*S): permuted origin, Woop shear, the
# permuted direction (DU, DV, DK), the exit distance from the grid (-inf = ray
# not live) and t_min. The walk only reads it: a store into it inside the ray
# loop would stop LLVM from vectorizing that loop (it cannot prove the rows
# disjoint). DU and DV are read only by the shared-origin (camera, point light) walk.
OU, OV, OK, SU, SV, SZ, DK, TEXIT, WTMIN, DU, DV = 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10
N_WORK = 11
# rows of the `sub` array (N_SUB_ROWS, n_sub + 1): frustum bounds of each
# sub-packet, column n_sub holds the whole packet's; WMIN/WMAX bound where
# along K the sub-packet's rays live (rays with their own origins and ends:
# shadow rays), so that triangles before or past all of them are skipped
UMIN, UMAX, GUMIN, GUMAX, VMIN, VMAX, GVMIN, GVMAX, WMIN, WMAX = 0, 1, 2, 3, 4, 5, 6, 7, 8, 9
N_SUB_ROWS = 10
MAILBOX_SIZE = 256            # power of two; collisions only cost a re-test


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
    K, s = pick_axis(mn0, mn1, mn2, mx0, mx1, mx2)
    return K, s, n_active


@kernel
def pick_axis(mn0, mn1, mn2, mx0, mx1, mx2):
    """(axis, sign) from per-axis direction ranges: the axis whose range
    excludes 0 with the largest margin; (-1, 0) if none does."""
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
    return best, best_sign


@helper
def slab_exit(ox, oy, oz, ix, iy, iz, t0, t1, g_lo, g_hi):
    """(t_enter, t_exit) of a ray in the grid box, branch-free: a zero
    direction gives +-inf bounds, and a 0 * inf NaN (origin on a slab plane)
    loses every min/max. Outside when t_enter > t_exit."""
    xa = (g_lo[0] - ox) * ix
    xb = (g_hi[0] - ox) * ix
    ya = (g_lo[1] - oy) * iy
    yb = (g_hi[1] - oy) * iy
    za = (g_lo[2] - oz) * iz
    zb = (g_hi[2] - oz) * iz
    t0 = max(t0, min(xa, xb))
    t1 = min(t1, max(xa, xb))
    t0 = max(t0, min(ya, yb))
    t1 = min(t1, max(ya, yb))
    t0 = max(t0, min(za, zb))
    t1 = min(t1, max(za, zb))
    return t0, t1


@kernel
def setup_rays(rays, work, sub, sub_active, g_lo, g_hi, eps):
    """Set-up for rays with arbitrary origins (shadow rays, ray batches).

    Returns (K, s, n_live, k_ref, w_end): major axis and its direction sign,
    the rays inside the grid, the packet's entry plane along K and its
    farthest exit in w. K = -1: no common axis (use single rays);
    n_live = 0: nothing to trace."""
    n_sub = rays.shape[1]
    ss = rays.shape[2]
    K, s, n_active = choose_major_axis(rays)
    if n_active == 0 or K < 0:
        return K, s, 0, F0, F0
    U = (K + 1) % 3
    V = (K + 2) % 3
    sf = np.float32(s)                 # float sign: an int would turn the math float64
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
            work[WTMIN, j, r] = rays[TMIN, j, r]
            work[DU, j, r] = rays[DX + U, j, r]       # read only by the shared-origin walk
            work[DV, j, r] = rays[DX + V, j, r]
            t0, t1 = slab_exit(rays[OX, j, r], rays[OY, j, r], rays[OZ, j, r],
                               F1 / rays[DX, j, r], F1 / rays[DY, j, r], F1 / rays[DZ, j, r],
                               rays[TMIN, j, r], rays[TMAX, j, r], g_lo, g_hi)
            inside = t0 <= t1
            work[TEXIT, j, r] = t1 if inside else -INF
            k_first = min(k_first, (ok + t0 * dk) * sf if inside else INF)
            k_last = max(k_last, (ok + t1 * dk) * sf if inside else -INF)
    if k_first > k_last:               # no ray enters the grid
        return K, s, 0, F0, F0
    k_ref = k_first * sf               # entry plane of the packet (w = 0)
    w_end = k_last - k_first           # farthest exit, in w
    n_live = 0
    for j in range(n_sub):
        u0 = v0 = gu0 = gv0 = w_lo = INF
        u1 = v1 = gu1 = gv1 = w_hi = -INF
        live = 0
        for r in range(ss):
            on = work[TEXIT, j, r] >= work[WTMIN, j, r]
            live += 1 if on else 0
            # a hit has t in (t_min, t_exit]: w is increasing in t
            ok_r = work[OK, j, r]
            w_lo = min(w_lo, (ok_r + work[WTMIN, j, r] * work[DK, j, r] - k_ref) * sf if on else INF)
            w_hi = max(w_hi, (ok_r + work[TEXIT, j, r] * work[DK, j, r] - k_ref) * sf if on else -INF)
            dk_ref = k_ref - work[OK, j, r]
            u = work[OU, j, r] + dk_ref * work[SU, j, r]
            v = work[OV, j, r] + dk_ref * work[SV, j, r]
            gu = work[SU, j, r] * sf
            gv = work[SV, j, r] * sf
            u0 = min(u0, u if on else INF)
            u1 = max(u1, u if on else -INF)
            v0 = min(v0, v if on else INF)
            v1 = max(v1, v if on else -INF)
            gu0 = min(gu0, gu if on else INF)
            gu1 = max(gu1, gu if on else -INF)
            gv0 = min(gv0, gv if on else INF)
            gv1 = max(gv1, gv if on else -INF)
        sub_active[j] = live
        n_live += live
        set_bounds(sub, j, u0, u1, gu0, gu1, v0, v1, gv0, gv1, eps)
        sub[WMIN, j] = w_lo - eps
        sub[WMAX, j] = w_hi + eps
    packet_bounds(sub, sub_active)
    return K, s, n_live, k_ref, w_end


@helper
def set_bounds(sub, j, u0, u1, gu0, gu1, v0, v1, gv0, gv1, eps):
    """Store the frustum bounds of sub-packet j, loosened by eps (its depth
    range WMIN/WMAX unbounded: the caller narrows it where it knows it)."""
    sub[UMIN, j] = u0 - eps
    sub[UMAX, j] = u1 + eps
    sub[GUMIN, j] = gu0
    sub[GUMAX, j] = gu1
    sub[VMIN, j] = v0 - eps
    sub[VMAX, j] = v1 + eps
    sub[GVMIN, j] = gv0
    sub[GVMAX, j] = gv1
    sub[WMIN, j] = -INF
    sub[WMAX, j] = INF


@helper
def packet_bounds(sub, sub_active):
    """Column n_sub = union of the bounds of the sub-packets with live rays."""
    n_sub = sub_active.shape[0]
    for row in (UMIN, GUMIN, VMIN, GVMIN):
        sub[row, n_sub] = INF
    for row in (UMAX, GUMAX, VMAX, GVMAX):
        sub[row, n_sub] = -INF
    for j in range(n_sub):
        if sub_active[j] > 0:
            for row in (UMIN, GUMIN, VMIN, GVMIN):
                sub[row, n_sub] = min(sub[row, n_sub], sub[row, j])
            for row in (UMAX, GUMAX, VMAX, GVMAX):
                sub[row, n_sub] = max(sub[row, n_sub], sub[row, j])


@helper
def _cull_plane(au, wa, bu, wb, cu, wc, g, bound, lower):
    """True when all three vertices lie outside the plane u - g*w = bound
    (below it for a lower bound, above it for an upper one)."""
    if lower:
        return (au - g * wa < bound) & (bu - g * wb < bound) & (cu - g * wc < bound)
    return (au - g * wa > bound) & (bu - g * wb > bound) & (cu - g * wc > bound)


@helper
def _culled(au, av, wa, bu, bv, wb, cu, cv, wc, sub, j):
    """Triangle outside one of the four side planes of frustum column j."""
    return (_cull_plane(au, wa, bu, wb, cu, wc, sub[GUMIN, j], sub[UMIN, j], True)
            or _cull_plane(au, wa, bu, wb, cu, wc, sub[GUMAX, j], sub[UMAX, j], False)
            or _cull_plane(av, wa, bv, wb, cv, wc, sub[GVMIN, j], sub[VMIN, j], True)
            or _cull_plane(av, wa, bv, wb, cv, wc, sub[GVMAX, j], sub[VMAX, j], False))


@helper
def _edge_normal(pu, pv, pk, qu, qv, qk):
    """p x q for two eye-relative vertices, computed as s x (t - s) with s the
    lexicographically smaller of the two: no cancellation between two long,
    nearly parallel vectors (a small far triangle otherwise lost 1e-2 of its
    barycentric accuracy), and the two triangles sharing an edge still get
    exact negatives of one vector (watertight: same s, t, opposite sign)."""
    swap = (pu > qu) or (pu == qu and (pv > qv or (pv == qv and pk > qk)))
    su, sv, sk = (qu, qv, qk) if swap else (pu, pv, pk)
    tu, tv, tk = (pu, pv, pk) if swap else (qu, qv, qk)
    du, dv, dk = tu - su, tv - sv, tk - sk
    nu = sv * dk - sk * dv
    nv = sk * du - su * dk
    nk = su * dv - sv * du
    if swap:
        return -nu, -nv, -nk
    return nu, nv, nk


@kernel
def walk(work, hit_t, hit_b1, hit_b2, hit_prim, any_hit, shared_origin, K, s, k_ref, w_end,
         sub, sub_done, sub_skip, mailbox, grid, tri_verts, eps, counters, tile, cull):
    """Walk the grid slice by slice along K for a set-up packet, updating the
    closest hits (hit_t must hold each ray's t_max, hit_prim -1 on entry).

    shared_origin: every ray starts at work[OU/OV/OK, 0, 0] (camera packets).
    cull False turns off the mailbox and the frustum culling of triangles
    (packet and sub-packets), for `frustrace compare` to measure what they save.
    The triangle is then tested through its three edge planes through that
    origin, computed once per triangle: per ray only three dot products,
    about half the work of the per-ray Woop shear. It is watertight for the
    same reason: a shared edge's plane normal is the exact negative of its
    neighbour's (cross products without FMA contraction), and zero is inclusive.
    The distance comes from the triangle's plane (normal from its edges).
    """
    g_lo, _, g_dims, g_cell, g_inv, cell_start, cell_tris = grid
    n_sub = work.shape[1]
    ss = work.shape[2]
    U = (K + 1) % 3
    V = (K + 2) % 3
    sf = np.float32(s)                 # float sign: an int would turn the math float64
    # counters live in scalars: a store to the counters array inside the loops
    # could alias every other array, forcing LLVM to reload them all
    n_cells = 0
    n_tests = 0
    n_cand = 0
    for j in range(n_sub):
        sub_done[j] = 0
    for m in range(MAILBOX_SIZE):
        mailbox[m] = -1
    pu0 = sub[UMIN, n_sub]
    pu1 = sub[UMAX, n_sub]
    pgu0 = sub[GUMIN, n_sub]
    pgu1 = sub[GUMAX, n_sub]
    pv0 = sub[VMIN, n_sub]
    pv1 = sub[VMAX, n_sub]
    pgv0 = sub[GVMIN, n_sub]
    pgv1 = sub[GVMAX, n_sub]
    e_u = work[OU, 0, 0]
    e_v = work[OV, 0, 0]
    e_k = work[OK, 0, 0]
    lo_k = g_lo[K]
    nK = g_dims[K]
    nU = g_dims[U]
    nV = g_dims[V]
    stride = (np.int64(1), np.int64(g_dims[0]), np.int64(g_dims[0]) * g_dims[1])
    sK = stride[K]
    sU = stride[U]
    sV = stride[V]
    q = min(max(int(np.floor((k_ref - lo_k) * g_inv[K])), 0), nK - 1)
    q_last = min(max(int(np.floor((k_ref + s * w_end - lo_k) * g_inv[K])), 0), nK - 1)
    n_slices = (q_last - q) * s + 1
    for _ in range(n_slices):
        k_lo = lo_k + np.float32(q) * g_cell[K]
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
                    n_cells += 1
                    for jj in range(cell_start[cell], cell_start[cell + 1]):
                        tri = cell_tris[jj]
                        slot = tri & (MAILBOX_SIZE - 1)
                        if cull and mailbox[slot] == tri:
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
                        wa = (ak - k_ref) * sf
                        wb = (bk - k_ref) * sf
                        wc = (ck - k_ref) * sf
                        if cull and (max(wa, wb, wc) < -eps or min(wa, wb, wc) > w_end + eps):
                            continue
                        # packet frustum: all vertices outside one plane -> cull
                        if cull and _culled(au, av, wa, bu, bv, wb, cu, cv, wc, sub, n_sub):
                            continue
                        n_cand += 1
                        if shared_origin:
                            # edge planes through the eye: n0 = b x c, n1 = c x a, n2 = a x b
                            xu, xv, xk = au - e_u, av - e_v, ak - e_k
                            yu, yv, yk = bu - e_u, bv - e_v, bk - e_k
                            zu, zv, zk = cu - e_u, cv - e_v, ck - e_k
                            n0u, n0v, n0k = _edge_normal(yu, yv, yk, zu, zv, zk)
                            n1u, n1v, n1k = _edge_normal(zu, zv, zk, xu, xv, xk)
                            n2u, n2v, n2k = _edge_normal(xu, xv, xk, yu, yv, yk)
                            # distance from the triangle's own plane: its normal
                            # from edges is well conditioned, unlike the sum of
                            # the edge-plane normals for small, far triangles
                            e1u, e1v, e1k = bu - au, bv - av, bk - ak
                            e2u, e2v, e2k = cu - au, cv - av, ck - ak
                            pnu = e1v * e2k - e1k * e2v
                            pnv = e1k * e2u - e1u * e2k
                            pnk = e1u * e2v - e1v * e2u
                            t_num = xu * pnu + xv * pnv + xk * pnk
                        # cull against every sub-packet frustum and depth range in one
                        # branch-free loop (vectorized over sub-packets: bounds are SoA)
                        w_near = min(wa, wb, wc)
                        w_far = max(wa, wb, wc)
                        for j in range(n_sub):
                            out = (_cull_plane(au, wa, bu, wb, cu, wc, sub[GUMIN, j], sub[UMIN, j], True)
                                   | _cull_plane(au, wa, bu, wb, cu, wc, sub[GUMAX, j], sub[UMAX, j], False)
                                   | _cull_plane(av, wa, bv, wb, cv, wc, sub[GVMIN, j], sub[VMIN, j], True)
                                   | _cull_plane(av, wa, bv, wb, cv, wc, sub[GVMAX, j], sub[VMAX, j], False)
                                   | (w_far < sub[WMIN, j]) | (w_near > sub[WMAX, j]))
                            sub_skip[j] = (out & cull) | (sub_done[j] >= ss)
                        for j in range(n_sub):
                            if sub_skip[j]:
                                continue
                            n_tests += ss
                            if shared_origin:
                                # branch-free ray loop over the sub-packet (vectorized)
                                for r in range(ss):
                                    du = work[DU, j, r]
                                    dv = work[DV, j, r]
                                    dk = work[DK, j, r]
                                    e0 = du * n0u + dv * n0v + dk * n0k
                                    e1 = du * n1u + dv * n1v + dk * n1k
                                    e2 = du * n2u + dv * n2v + dk * n2k
                                    outside = (((e0 < F0) | (e1 < F0) | (e2 < F0))
                                               & ((e0 > F0) | (e1 > F0) | (e2 > F0)))
                                    det = e0 + e1 + e2
                                    inv_det = F1 / det
                                    t = t_num / (du * pnu + dv * pnv + dk * pnk)
                                    better = ((not outside) & (det != F0) & (t > work[WTMIN, j, r])
                                              & (t < hit_t[j, r]))
                                    hit_t[j, r] = t if better else hit_t[j, r]
                                    hit_b1[j, r] = e1 * inv_det if better else hit_b1[j, r]
                                    hit_b2[j, r] = e2 * inv_det if better else hit_b2[j, r]
                                    hit_prim[j, r] = tri if better else hit_prim[j, r]
                                continue
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
                                better = hit & (t > work[WTMIN, j, r]) & (t < hit_t[j, r])
                                hit_t[j, r] = t if better else hit_t[j, r]
                                hit_b1[j, r] = b1 if better else hit_b1[j, r]
                                hit_b2[j, r] = b2 if better else hit_b2[j, r]
                                hit_prim[j, r] = tri if better else hit_prim[j, r]
        # --- stop once every ray is finished before the end of this slice ----
        # (finishing is monotone: a finished sub-packet is never recounted;
        # rays that never entered the grid count as finished)
        done = 0
        for j in range(n_sub):
            if sub_done[j] < ss:
                dj = 0
                for r in range(ss):
                    t_far = min(hit_t[j, r], work[TEXIT, j, r])
                    w_far = (work[OK, j, r] + t_far * work[DK, j, r] - k_ref) * sf
                    fin = (w_far <= w1) | (any_hit & (hit_prim[j, r] >= 0))
                    dead = work[TEXIT, j, r] < work[WTMIN, j, r]
                    dj += 1 if (fin | dead) else 0
                sub_done[j] = dj
            done += sub_done[j]
        if done >= n_sub * ss:
            break
        q += s
    counters[tile, PACKETS] += 1
    counters[tile, VISITS] += n_cells
    counters[tile, TESTS] += n_tests
    counters[tile, CANDIDATES] += n_cand
