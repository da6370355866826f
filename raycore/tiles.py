"""Tiles handed to the cores with dynamic load balancing.

One prange iteration per thread; each thread allocates its packet scratch once
and then pulls tile indices from a shared atomic counter until none are left,
so a thread that drew cheap tiles (sky) takes more of them. Tiles are square,
a multiple of the packet size, and many more than the threads.

Two drivers share the packet machinery: primary rays from the camera, and
shadow rays from visible surface points to one light.
"""
import numpy as np
from numba import prange

from ._jit import fetch_add, kernel, parallel_kernel
from .camera import primary_dir
from .grid_cgt import (DX, DY, DZ, MAILBOX_SIZE, OX, OY, OZ, TMAX, TMIN,
                       cgt_packet)
from .grid_dda import dda_trace
from .triangle import surface_point


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
def _packet_pixel(px, py, i, packet, sub_size):
    """Pixel of ray slot i in the packet at (px, py): sub-packet-major order."""
    ss = sub_size * sub_size
    j = i // ss
    r = i - j * ss
    n_sx = packet // sub_size
    x = px + (j % n_sx) * sub_size + r % sub_size
    y = py + (j // n_sx) * sub_size + r // sub_size
    return x, y


@kernel
def _trace_or_fallback(rays, work, hit_t, hit_b1, hit_b2, hit_prim, n_rays, sub_size,
                       any_hit, sub, sub_active, sub_done, mailbox,
                       g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris,
                       tri_verts, eps, counters, tile):
    """CGT for the packet, or single-ray DDA for each ray if it has no common
    major axis (rays pointing to both sides of every axis)."""
    ok = cgt_packet(rays, work, hit_t, hit_b1, hit_b2, hit_prim, n_rays, sub_size,
                    any_hit, sub, sub_active, sub_done, mailbox,
                    g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris,
                    tri_verts, eps, counters, tile)
    if ok:
        return
    for i in range(n_rays):
        hit_t[i] = rays[TMAX, i]
        hit_prim[i] = -1
        if rays[TMAX, i] > rays[TMIN, i]:
            t, prim, b1, b2, cells, tests = dda_trace(
                rays[OX, i], rays[OY, i], rays[OZ, i], rays[DX, i], rays[DY, i], rays[DZ, i],
                rays[TMIN, i], rays[TMAX, i], any_hit,
                g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris, tri_verts)
            hit_t[i] = t
            hit_prim[i] = prim
            hit_b1[i] = b1
            hit_b2[i] = b2
            counters[tile, 1] += cells
            counters[tile, 2] += tests
            counters[tile, 4] += 1


@parallel_kernel
def trace_primary(cam, width, height, jx, jy, packet, sub_size, tile_size, n_workers,
                  g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris, tri_verts, eps,
                  out_t, out_prim, out_b1, out_b2, counters):
    """Closest hits of the camera rays (sub-pixel offset jx, jy) for every pixel.

    out_*: (height * width,) arrays, row-major from the top; out_prim -1 = miss.
    counters: (n_tiles, N_COUNTERS) int64, one row per tile (no shared writes).
    """
    tiles_x = (width + tile_size - 1) // tile_size
    tiles_y = (height + tile_size - 1) // tile_size
    n_tiles = tiles_x * tiles_y
    n_rays = packet * packet
    n_sub = n_rays // (sub_size * sub_size)
    next_tile = np.zeros(1, np.int64)
    for _w in prange(n_workers):
        rays = np.empty((8, n_rays), np.float32)
        work = np.empty((8, n_rays), np.float32)
        hit_t = np.empty(n_rays, np.float32)
        hit_b1 = np.zeros(n_rays, np.float32)
        hit_b2 = np.zeros(n_rays, np.float32)
        hit_prim = np.empty(n_rays, np.int32)
        sub = np.empty((8, n_sub), np.float32)
        sub_active = np.empty(n_sub, np.int32)
        sub_done = np.empty(n_sub, np.int32)
        mailbox = np.empty(MAILBOX_SIZE, np.int32)
        while True:
            tile = fetch_add(next_tile, 0, 1)
            if tile >= n_tiles:
                break
            tx0 = (tile % tiles_x) * tile_size
            ty0 = (tile // tiles_x) * tile_size
            for py in range(ty0, min(ty0 + tile_size, height), packet):
                for px in range(tx0, min(tx0 + tile_size, width), packet):
                    for i in range(n_rays):
                        x, y = _packet_pixel(px, py, i, packet, sub_size)
                        inside = x < width and y < height
                        dx, dy, dz = primary_dir(cam, min(x, width - 1), min(y, height - 1),
                                                 jx, jy, width, height)
                        rays[OX, i] = cam[0]
                        rays[OY, i] = cam[1]
                        rays[OZ, i] = cam[2]
                        rays[DX, i] = dx
                        rays[DY, i] = dy
                        rays[DZ, i] = dz
                        rays[TMIN, i] = 0.0
                        rays[TMAX, i] = np.inf if inside else -1.0
                    _trace_or_fallback(rays, work, hit_t, hit_b1, hit_b2, hit_prim, n_rays,
                                       sub_size, False, sub, sub_active, sub_done, mailbox,
                                       g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris,
                                       tri_verts, eps, counters, tile)
                    for i in range(n_rays):
                        x, y = _packet_pixel(px, py, i, packet, sub_size)
                        if x < width and y < height:
                            p = y * width + x
                            out_t[p] = hit_t[i]
                            out_prim[p] = hit_prim[i]
                            out_b1[p] = hit_b1[i]
                            out_b2[p] = hit_b2[i]


@parallel_kernel
def trace_shadows(cam, width, height, jx, jy, packet, sub_size, tile_size, n_workers,
                  light_kind, lx, ly, lz, offset_scale,
                  g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris, tri_verts, eps,
                  hit_prim, hit_b1, hit_b2, out_vis, counters):
    """Visibility (1 lit, 0 shadowed) of one light from every visible point.

    light_kind 0 = point light at (lx, ly, lz); 1 = directional light shining
    along (lx, ly, lz). Origins are pushed off the surface along the geometric
    normal (turned to face the camera) by offset_scale * (|p|max + 1): enough to
    escape the float32 rounding of p, far below the size of any real gap.
    Points whose surface faces away from the light get 0 without a ray.
    """
    tiles_x = (width + tile_size - 1) // tile_size
    tiles_y = (height + tile_size - 1) // tile_size
    n_tiles = tiles_x * tiles_y
    n_rays = packet * packet
    n_sub = n_rays // (sub_size * sub_size)
    next_tile = np.zeros(1, np.int64)
    for _w in prange(n_workers):
        rays = np.empty((8, n_rays), np.float32)
        work = np.empty((8, n_rays), np.float32)
        hit_t = np.empty(n_rays, np.float32)
        hit_b1 = np.zeros(n_rays, np.float32)
        hit_b2 = np.zeros(n_rays, np.float32)
        hit_p = np.empty(n_rays, np.int32)
        sub = np.empty((8, n_sub), np.float32)
        sub_active = np.empty(n_sub, np.int32)
        sub_done = np.empty(n_sub, np.int32)
        mailbox = np.empty(MAILBOX_SIZE, np.int32)
        while True:
            tile = fetch_add(next_tile, 0, 1)
            if tile >= n_tiles:
                break
            tx0 = (tile % tiles_x) * tile_size
            ty0 = (tile // tiles_x) * tile_size
            for py in range(ty0, min(ty0 + tile_size, height), packet):
                for px in range(tx0, min(tx0 + tile_size, width), packet):
                    for i in range(n_rays):
                        x, y = _packet_pixel(px, py, i, packet, sub_size)
                        rays[TMIN, i] = 0.0
                        rays[TMAX, i] = -1.0          # inactive unless set below
                        rays[OX, i] = cam[0]
                        rays[OY, i] = cam[1]
                        rays[OZ, i] = cam[2]
                        rays[DX, i] = cam[3]
                        rays[DY, i] = cam[4]
                        rays[DZ, i] = cam[5]
                        if x >= width or y >= height:
                            continue
                        p = y * width + x
                        prim = hit_prim[p]
                        if prim < 0:
                            continue
                        sx, sy, sz, nx, ny, nz = surface_point(tri_verts, prim, hit_b1[p], hit_b2[p])
                        vx, vy, vz = primary_dir(cam, x, y, jx, jy, width, height)
                        if nx * vx + ny * vy + nz * vz > 0.0:
                            nx, ny, nz = -nx, -ny, -nz
                        big = max(abs(sx), abs(sy), abs(sz))
                        off = offset_scale * (big + 1.0)
                        ox = sx + nx * off
                        oy = sy + ny * off
                        oz = sz + nz * off
                        if light_kind == 0:
                            dx = lx - ox
                            dy = ly - oy
                            dz = lz - oz
                        else:
                            dx = -lx
                            dy = -ly
                            dz = -lz
                        dist = np.sqrt(dx * dx + dy * dy + dz * dz)
                        if dist == 0.0 or nx * dx + ny * dy + nz * dz <= 0.0:
                            out_vis[p] = 0.0
                            continue
                        rays[OX, i] = ox
                        rays[OY, i] = oy
                        rays[OZ, i] = oz
                        rays[DX, i] = dx / dist
                        rays[DY, i] = dy / dist
                        rays[DZ, i] = dz / dist
                        rays[TMAX, i] = dist * (1.0 - 1e-6) if light_kind == 0 else np.inf
                    _trace_or_fallback(rays, work, hit_t, hit_b1, hit_b2, hit_p, n_rays,
                                       sub_size, True, sub, sub_active, sub_done, mailbox,
                                       g_lo, g_hi, g_dims, g_cell, g_inv, cell_start, cell_tris,
                                       tri_verts, eps, counters, tile)
                    for i in range(n_rays):
                        x, y = _packet_pixel(px, py, i, packet, sub_size)
                        if x < width and y < height and rays[TMAX, i] > rays[TMIN, i]:
                            out_vis[y * width + x] = 1.0 if hit_p[i] < 0 else 0.0
