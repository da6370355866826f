"""Tiles handed to the cores with dynamic load balancing.

One prange iteration per thread; each thread allocates its packet scratch once
and then pulls tile indices from a shared atomic counter until none are left,
so a thread that drew cheap tiles (sky) takes more of them. Tiles are square,
a multiple of the packet size, and many more than the threads.

Two drivers share the packet machinery here: primary rays from the camera,
and batches of arbitrary rays; shadow rays have their own order and driver
(shadow_packets.py).
"""
import numpy as np
from numba import prange

from ._jit import fetch_add, helper, kernel, parallel_kernel
from .camera import primary_dir
from .grid_cgt import (DK, DX, DY, DZ, F0, F1, INF, MAILBOX_SIZE, N_SUB_ROWS, N_WORK, OK, OU, OV,
                       OX, OY, OZ, SU, SV, SZ, DU, DV, TEXIT, TMAX, TMIN, WTMIN, packet_bounds,
                       pick_axis, set_bounds, setup_rays, walk)
from .grid_dda import dda_trace


def tile_size_for(width: int, height: int, packet: int, threads: int) -> int:
    """Largest tile (packet multiple, <= 64 px, >= packet) that still gives at
    least 16 tiles per thread, so the queue can balance the load."""
    size = max(packet, 64 // packet * packet)
    while size > packet:
        n_tiles = -(-width // size) * -(-height // size)
        if n_tiles >= 16 * max(threads, 1):
            break
        size -= packet
    return size


@kernel
def _tile_count(width, height, tile_size):
    """(tiles per row, tiles in all) of an image cut into square tiles."""
    tiles_x = (width + tile_size - 1) // tile_size
    return tiles_x, tiles_x * ((height + tile_size - 1) // tile_size)


@kernel
def _tile_corner(tile, tiles_x, tile_size):
    """Top-left pixel of tile number `tile` (row-major over the tiles)."""
    return (tile % tiles_x) * tile_size, (tile // tiles_x) * tile_size


@kernel
def _sub_corner(px, py, j, packet, sub_size):
    """Top-left pixel of sub-packet j of the packet whose corner is (px, py).
    Ray r = ly * sub_size + lx of that sub-packet is pixel (x0 + lx, y0 + ly)."""
    n_sx = packet // sub_size
    return px + (j % n_sx) * sub_size, py + (j // n_sx) * sub_size


@kernel
def _ray_offsets(sub_size):
    """(lx, ly) of ray r in a sub-packet, as tables so that per-ray loops run
    over r alone (no division, vectorizable)."""
    ss = sub_size * sub_size
    lx = np.empty(ss, np.int64)
    ly = np.empty(ss, np.int64)
    for r in range(ss):
        lx[r] = r % sub_size
        ly[r] = r // sub_size
    return lx, ly


@kernel
def _scratch(packet, sub_size):
    """One thread's packet scratch: rays (8, n_sub, ss), work (N_WORK, n_sub,
    ss), hit t/b1/b2/prim (n_sub, ss), sub bounds (N_SUB_ROWS, n_sub + 1), sub-packet
    live and done counts, mailbox."""
    ss = sub_size * sub_size
    n_sub = packet * packet // ss
    return (np.empty((8, n_sub, ss), np.float32), np.empty((N_WORK, n_sub, ss), np.float32),
            np.empty((n_sub, ss), np.float32), np.zeros((n_sub, ss), np.float32),
            np.zeros((n_sub, ss), np.float32), np.empty((n_sub, ss), np.int32),
            np.empty((N_SUB_ROWS, n_sub + 1), np.float32), np.empty(n_sub, np.int32),
            np.empty(n_sub, np.int32), np.empty(n_sub, np.bool_), np.empty(MAILBOX_SIZE, np.int32))


@kernel
def _dda_packet(rays, hit_t, hit_b1, hit_b2, hit_prim, any_hit,
                g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris, tri_verts,
                counters, tile):
    """Single-ray DDA for every active ray of a packet that has no common
    major axis (its rays point to both sides of every axis)."""
    for j in range(rays.shape[1]):
        for r in range(rays.shape[2]):
            hit_t[j, r] = rays[TMAX, j, r]
            hit_prim[j, r] = -1
            if rays[TMAX, j, r] > rays[TMIN, j, r]:
                t, prim, b1, b2, cells, tests = dda_trace(
                    rays[OX, j, r], rays[OY, j, r], rays[OZ, j, r],
                    rays[DX, j, r], rays[DY, j, r], rays[DZ, j, r],
                    rays[TMIN, j, r], rays[TMAX, j, r], any_hit,
                    g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris, tri_verts)
                hit_t[j, r] = t
                hit_prim[j, r] = prim
                hit_b1[j, r] = b1
                hit_b2[j, r] = b2
                counters[tile, 1] += cells
                counters[tile, 2] += tests
                counters[tile, 4] += 1


@kernel
def trace_or_fallback(rays, work, hit_t, hit_b1, hit_b2, hit_prim, any_hit, shared_origin, sub,
                      sub_active, sub_done, sub_skip, mailbox,
                      g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris,
                      tri_verts, eps, counters, tile, cull):
    """CGT for a packet of arbitrary rays, or single-ray DDA when the rays
    share no major axis. Fills hit_* (prim -1: nothing before TMAX).
    shared_origin: every ray, padding included, starts at one point (rays
    from a point light), which allows the cheaper edge-plane test."""
    for j in range(rays.shape[1]):
        for r in range(rays.shape[2]):
            hit_t[j, r] = rays[TMAX, j, r]
            hit_prim[j, r] = -1
    K, s, n_live, k_ref, w_end = setup_rays(rays, work, sub, sub_active, g_lo, g_hi, eps)
    if K < 0:
        _dda_packet(rays, hit_t, hit_b1, hit_b2, hit_prim, any_hit, g_lo, g_hi, g_dims,
                    g_cell, g_inv, cell_start, cell_tris, tri_verts, counters, tile)
    elif n_live > 0:
        walk(work, hit_t, hit_b1, hit_b2, hit_prim, any_hit, shared_origin, K, s, k_ref, w_end,
             sub, sub_done, sub_skip, mailbox, g_lo, g_dims, g_cell, g_inv,
             cell_start, cell_tris, tri_verts, eps, counters, tile, cull)


@helper
def _camera_rays(rays, cam, px, py, packet, sub_size, width, height, jx, jy, off_x, off_y):
    """The packet's camera rays as general rays (for the DDA fallback)."""
    for j in range(rays.shape[1]):
        x0, y0 = _sub_corner(px, py, j, packet, sub_size)
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
        x0, y0 = _sub_corner(px, py, j, packet, sub_size)
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


@parallel_kernel
def trace_primary(cam, width, height, jx, jy, packet, sub_size, tile_size, n_workers,
                  g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris, tri_verts, eps,
                  sw_t, sw_prim, sw_b1, sw_b2, counters, cull):
    """Closest hits of the camera rays (sub-pixel offset jx, jy) for every pixel.

    sw_*: packet-major hits (n_packets, n_sub, S*S), packet (px, py) at index
    (py // packet) * packets_x + px // packet, ray r of sub-packet j as in
    _sub_corner; each packet traces straight into its own slot (copying hits
    out to row-major order inside the traversal cost a third of its time).
    `unswizzle` turns them into row-major images. prim -1 = miss.
    counters: (n_tiles, N_COUNTERS) int64, one row per tile (no shared writes).
    """
    tiles_x, n_tiles = _tile_count(width, height, tile_size)
    next_tile = np.zeros(1, np.int64)
    packets_x = (width + packet - 1) // packet
    for _w in prange(n_workers):
        rays, work, _t, _b1, _b2, _prim, sub, sub_active, sub_done, sub_skip, mailbox = \
            _scratch(packet, sub_size)
        off_x, off_y = _ray_offsets(sub_size)
        while True:
            tile = fetch_add(next_tile, 0, 1)
            if tile >= n_tiles:
                break
            tx0, ty0 = _tile_corner(tile, tiles_x, tile_size)
            for py in range(ty0, min(ty0 + tile_size, height), packet):
                for px in range(tx0, min(tx0 + tile_size, width), packet):
                    pk = (py // packet) * packets_x + px // packet
                    hit_t = sw_t[pk]
                    hit_prim = sw_prim[pk]
                    hit_b1 = sw_b1[pk]
                    hit_b2 = sw_b2[pk]
                    K, s, n_live, k_ref, w_end = setup_camera(
                        cam, px, py, packet, sub_size, width, height, jx, jy, off_x, off_y,
                        work, hit_t, hit_prim, sub, sub_active, g_lo, g_hi, eps)
                    if K < 0:
                        _camera_rays(rays, cam, px, py, packet, sub_size, width, height,
                                     jx, jy, off_x, off_y)
                        _dda_packet(rays, hit_t, hit_b1, hit_b2, hit_prim, False, g_lo, g_hi,
                                    g_dims, g_cell, g_inv, cell_start, cell_tris, tri_verts,
                                    counters, tile)
                    elif n_live > 0:
                        walk(work, hit_t, hit_b1, hit_b2, hit_prim, False, True, K, s,
                             k_ref, w_end, sub, sub_done, sub_skip, mailbox, g_lo, g_dims,
                             g_cell, g_inv, cell_start, cell_tris, tri_verts, eps, counters, tile,
                             cull)


def swizzle_offsets(width, height, packet, sub_size):
    """Row and column terms of the packet-major index of pixel (x, y):
    flat index into sw_*.reshape(-1) = row_off[y] + col_off[x]."""
    n_sx = packet // sub_size
    ss = sub_size * sub_size
    n_sub = n_sx * n_sx
    packets_x = -(-width // packet)
    y = np.arange(height)
    x = np.arange(width)
    row_off = ((y // packet) * packets_x * n_sub * ss + ((y % packet) // sub_size) * n_sx * ss
               + (y % sub_size) * sub_size)
    col_off = (x // packet) * n_sub * ss + ((x % packet) // sub_size) * ss + x % sub_size
    return row_off.astype(np.int64), col_off.astype(np.int64)


@parallel_kernel
def unswizzle(sw_t, sw_prim, sw_b1, sw_b2, row_off, col_off, out_t, out_prim, out_b1, out_b2):
    """Packet-major hits -> row-major (H*W,) images (a gather per pixel)."""
    width = col_off.shape[0]
    for y in prange(row_off.shape[0]):
        base = row_off[y]
        p0 = y * width
        for x in range(width):
            k = base + col_off[x]
            out_t[p0 + x] = sw_t[k]
            out_prim[p0 + x] = sw_prim[k]
            out_b1[p0 + x] = sw_b1[k]
            out_b2[p0 + x] = sw_b2[k]


@parallel_kernel
def trace_ray_batch(origins, dirs, t_min, t_max, packet, sub_size, n_workers, any_hit,
                    g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris, tri_verts, eps,
                    out_t, out_prim, out_b1, out_b2, counters, cull):
    """Arbitrary rays (n, 3) f32, grouped into packets of packet^2 consecutive
    rays (the caller orders them coherently); same kernels as the camera path.
    counters: (n_packets, N_COUNTERS) int64."""
    n = origins.shape[0]
    ss = sub_size * sub_size
    n_sub = packet * packet // ss
    per_packet = n_sub * ss
    n_packets = (n + per_packet - 1) // per_packet
    next_packet = np.zeros(1, np.int64)
    for _w in prange(n_workers):
        rays, work, hit_t, hit_b1, hit_b2, hit_prim, sub, sub_active, sub_done, sub_skip, mailbox = \
            _scratch(packet, sub_size)
        while True:
            pk = fetch_add(next_packet, 0, 1)
            if pk >= n_packets:
                break
            for j in range(n_sub):
                for r in range(ss):
                    i = pk * per_packet + j * ss + r
                    k = min(i, n - 1)
                    for a in range(3):
                        rays[OX + a, j, r] = origins[k, a]
                        rays[DX + a, j, r] = dirs[k, a]
                    rays[TMIN, j, r] = t_min[k]
                    rays[TMAX, j, r] = t_max[k] if i < n else -F1
            trace_or_fallback(rays, work, hit_t, hit_b1, hit_b2, hit_prim, any_hit, False,
                              sub, sub_active, sub_done, sub_skip, mailbox,
                              g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris,
                              tri_verts, eps, counters, pk, cull)
            for j in range(n_sub):
                for r in range(ss):
                    i = pk * per_packet + j * ss + r
                    if i < n:
                        out_t[i] = hit_t[j, r]
                        out_prim[i] = hit_prim[j, r]
                        out_b1[i] = hit_b1[j, r]
                        out_b2[i] = hit_b2[j, r]
