"""Plain-Python wrappers around the tile drivers: validate, allocate, call."""
from typing import NamedTuple

import numba
import numpy as np

from raycore.config import EPS_CULL_REL, PACKET_SIZES
from raycore.grid.build import Grid
from raycore.jit.counters import N_COUNTERS
from raycore.grid.drivers import trace_primary, trace_primary_on_threads, trace_ray_batch
from raycore.jit.launch import on_omp_threads
from raycore.grid.packet_layout import swizzle_offsets, unswizzle
from raycore.geometry.light_rays import SHADOW_PACKET, LightRays
from raycore.jit.thread_pool import on_threads
from raycore.jit.tile_queue import new_queue, tile_size_for

# Sub-packet size for culling and the vectorized ray loop. 4x4 cut the ray
# tests by a third but ran 2.5x slower (per-loop overhead); 8x8 measured best.
SUB = 8


class Hits(NamedTuple):
    """Closest hits per pixel: (H*W,) arrays row-major from the top, or the
    packet-major arrays trace_camera(row_major=False) returns."""
    t: np.ndarray        # f32 distance along the unit ray (inf on a miss)
    prim: np.ndarray     # i32 triangle index, -1 on a miss
    b1: np.ndarray       # f32 barycentric weight of vertex 1
    b2: np.ndarray       # f32 barycentric weight of vertex 2
    counters: np.ndarray  # (N_COUNTERS,) i64: packets, cells, tests, candidates, fallback rays
    inst: np.ndarray = None  # i32 instance of each hit in an instanced world (raycore/instancing), else None


def _sub_size(packet):
    """Side of the sub-packets a packet is culled and tested in."""
    return min(packet, SUB)


def _layout(width, height, packet):
    if packet not in PACKET_SIZES:
        raise ValueError(f"packet must be one of {PACKET_SIZES}, got {packet}")
    threads = numba.get_num_threads()
    tile = tile_size_for(width, height, packet, threads)
    n_tiles = -(-width // tile) * -(-height // tile)
    return _sub_size(packet), tile, n_tiles, threads


def _cull_eps(grid: Grid) -> np.float32:
    size = float(np.max(grid.hi - grid.lo))
    return np.float32(EPS_CULL_REL * max(size, 1e-30))


def hit_buffers(n: int) -> Hits:
    """Row-major output arrays for n rays. Reusing them across frames avoids
    ~4 ms of page faults per 1024^2 frame (fresh arrays are zero-filled)."""
    return Hits(np.empty(n, np.float32), np.empty(n, np.int32), np.empty(n, np.float32),
                np.empty(n, np.float32), None)


class CameraBuffers(NamedTuple):
    """Row-major hits plus the packet-major arrays the traversal writes and the
    index terms that map one to the other; reused across frames."""
    hits: Hits
    swizzled: tuple
    row_off: np.ndarray
    col_off: np.ndarray
    key: tuple


def camera_buffers(width, height, packet) -> CameraBuffers:
    sub = _sub_size(packet)
    n_packets = -(-width // packet) * -(-height // packet)
    shape = (n_packets, (packet // sub) ** 2, sub * sub)
    swizzled = (np.empty(shape, np.float32), np.empty(shape, np.int32),
                np.empty(shape, np.float32), np.empty(shape, np.float32))
    row_off, col_off = swizzle_offsets(width, height, packet, sub)
    return CameraBuffers(hit_buffers(width * height), swizzled, row_off, col_off,
                         (width, height, packet))


def row_major_offsets(width, height):
    """Index terms of plain row-major images: pixel (x, y) at y * W + x."""
    return np.arange(height, dtype=np.int64) * width, np.arange(width, dtype=np.int64)


def trace_camera(grid: Grid, tri_verts, cam, width, height, packet=8, jitter=(0.5, 0.5),
                 out: CameraBuffers = None, row_major=True, cull=True) -> Hits:
    """Trace one camera ray per pixel (at sub-pixel offset `jitter`); results
    go into `out` (from camera_buffers, same size and packet) when given.

    row_major=False skips the reordering pass (~3 ms per 1024^2 frame) and
    returns the packet-major arrays as written; pixel (x, y) is then at
    out.row_off[y] + out.col_off[x] (shading and shadows read them so)."""
    sub, tile, n_tiles, threads = _layout(width, height, packet)
    if out is None or out.key != (width, height, packet):
        out = camera_buffers(width, height, packet)
    sw_t, sw_prim, sw_b1, sw_b2 = out.swizzled
    counters = np.zeros((n_tiles, N_COUNTERS), np.int64)
    args = (new_queue(), cam, width, height, np.float32(jitter[0]), np.float32(jitter[1]), packet, sub,
            tile, grid, tri_verts, _cull_eps(grid), sw_t, sw_prim, sw_b1, sw_b2, counters, cull)
    on_omp_threads(trace_primary_on_threads, trace_primary, threads, *args)
    flat = (sw_t.reshape(-1), sw_prim.reshape(-1), sw_b1.reshape(-1), sw_b2.reshape(-1))
    if not row_major:
        return Hits(*flat, counters.sum(axis=0))
    h = out.hits
    unswizzle(*flat, out.row_off, out.col_off, h.t, h.prim, h.b1, h.b2)
    return Hits(h.t, h.prim, h.b1, h.b2, counters.sum(axis=0))


# hit outputs trace_ray_batch does not write: shadow rays give visibility only
NO_HITS = (np.zeros(0, np.float32), np.zeros(0, np.int32), np.zeros(0, np.float32), np.zeros(0, np.float32))


def light_visibility(grid: Grid, tri_verts, rays: LightRays, vis=None, packet=SHADOW_PACKET,
                     cull=True):
    """Visibility (n,) f32 (1 lit, 0 shadowed or facing away) of one light's
    shadow rays, traced in light-space packets, and the (N_COUNTERS,) counters."""
    n = rays.t_max.shape[0]
    sub = _sub_size(packet)
    threads = numba.get_num_threads()
    vis = np.empty(n, np.float32) if vis is None else vis
    vis[:] = 0.0
    n_packets = max(1, -(-rays.n_active // (packet * packet)))
    counters = np.zeros((n_packets, N_COUNTERS), np.int64)
    on_threads(trace_ray_batch, threads, rays.order, rays.n_active, rays.origin, rays.direction, rays.t_min,
               rays.t_max, packet, sub, new_queue(), True, rays.shared_origin, grid, tri_verts,
               _cull_eps(grid), *NO_HITS, vis, counters, cull)
    return vis, counters.sum(axis=0)


def trace_rays(grid: Grid, tri_verts, origins, dirs, t_min=None, t_max=None, packet=8,
               any_hit=False) -> Hits:
    """Closest (or any) hits of arbitrary rays, packet^2 consecutive rays per packet.
    Directions need not be unit length; t is in units of the given direction."""
    sub, _, _, threads = _layout(packet, packet, packet)
    origins = np.ascontiguousarray(origins, np.float32)
    dirs = np.ascontiguousarray(dirs, np.float32)
    n = origins.shape[0]
    t_min = np.zeros(n, np.float32) if t_min is None else np.ascontiguousarray(t_min, np.float32)
    t_max = np.full(n, np.inf, np.float32) if t_max is None else np.ascontiguousarray(t_max, np.float32)
    out_t = np.empty(n, np.float32)
    out_prim = np.empty(n, np.int32)
    out_b1 = np.empty(n, np.float32)
    out_b2 = np.empty(n, np.float32)
    counters = np.zeros((max(1, -(-n // (packet * packet))), N_COUNTERS), np.int64)
    order = np.arange(n, dtype=np.int32)
    on_threads(trace_ray_batch, threads, order, n, np.ascontiguousarray(origins.T), np.ascontiguousarray(dirs.T),
               t_min, t_max, packet, sub, new_queue(), any_hit, False, grid, tri_verts, _cull_eps(grid),
               out_t, out_prim, out_b1, out_b2, NO_HITS[0], counters, True)
    return Hits(out_t, out_prim, out_b1, out_b2, counters.sum(axis=0))
