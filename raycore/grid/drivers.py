"""The grid's drivers: every packet walk starts here. Camera packets
(trace_primary) and batches of rays (trace_ray_batch: arbitrary rays, and
shadow rays in light-space order) are pulled from the tile queue
(jit/tile_queue.py) by one worker per thread and traced by trace_or_fallback:
Coherent Grid Traversal (grid/cgt.walk), or single-ray DDA (grid/dda.py)
for a packet whose rays share no direction sign on any axis."""
from numba import prange

from raycore.jit.presets import helper, kernel, parallel_kernel
from raycore.grid.camera_packets import camera_rays, setup_camera
from raycore.jit.counters import FALLBACK_RAYS, TESTS, VISITS
from raycore.grid.cgt import DX, DY, DZ, OX, OY, OZ, TMAX, TMIN, setup_rays, walk
from raycore.grid.dda import dda_trace
from raycore.jit.launch import call_native
from raycore.grid.packet_layout import packet_scratch, ray_offsets
from raycore.jit.tile_queue import next_tile, tile_corner, tile_count
from raycore.jit.floats import F1


@kernel
def dda_packet(rays, hit_t, hit_b1, hit_b2, hit_prim, any_hit, grid, tri_verts, counters, tile):
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
                    rays[TMIN, j, r], rays[TMAX, j, r], any_hit, grid, tri_verts)
                hit_t[j, r] = t
                hit_prim[j, r] = prim
                hit_b1[j, r] = b1
                hit_b2[j, r] = b2
                counters[tile, VISITS] += cells
                counters[tile, TESTS] += tests
                counters[tile, FALLBACK_RAYS] += 1


@kernel
def trace_or_fallback(rays, work, hit_t, hit_b1, hit_b2, hit_prim, any_hit, shared_origin, sub,
                      sub_active, sub_done, sub_skip, mailbox, grid, tri_verts, eps, counters, tile,
                      cull):
    """CGT for a packet of arbitrary rays, or single-ray DDA when the rays
    share no major axis. Fills hit_* (prim -1: nothing before TMAX).
    shared_origin: every ray, padding included, starts at one point (rays
    from a point light), which allows the cheaper edge-plane test."""
    for j in range(rays.shape[1]):
        for r in range(rays.shape[2]):
            hit_t[j, r] = rays[TMAX, j, r]
            hit_prim[j, r] = -1
    K, s, n_live, k_ref, w_end = setup_rays(rays, work, sub, sub_active, grid.lo, grid.hi, eps)
    if K < 0:
        dda_packet(rays, hit_t, hit_b1, hit_b2, hit_prim, any_hit, grid, tri_verts, counters, tile)
    elif n_live > 0:
        walk(work, hit_t, hit_b1, hit_b2, hit_prim, any_hit, shared_origin, K, s, k_ref, w_end,
             sub, sub_done, sub_skip, mailbox, grid, tri_verts, eps, counters, tile, cull)


@kernel
def trace_primary(queue, cam, width, height, jx, jy, packet, sub_size, tile_size,
                  grid, tri_verts, eps, sw_t, sw_prim, sw_b1, sw_b2, counters, cull):
    """Closest hits of the camera rays (sub-pixel offset jx, jy) of the
    tiles this thread pulls from `queue` until none is left (grid/trace.py starts
    one per thread: trace_primary_on_threads, jit/launch.py).

    grid: grid/build.Grid over tri_verts. sw_*: packet-major hits
    (n_packets, n_sub, S*S), packet (px, py) at index
    (py // packet) * packets_x + px // packet, ray r of sub-packet j as in
    sub_corner; each packet traces straight into its own slot (copying hits
    out to row-major order inside the traversal cost a third of its time).
    `unswizzle` turns them into row-major images. prim -1 = miss.
    counters: (n_tiles, N_COUNTERS) int64, one row per tile (no shared writes).
    """
    tiles_x, n_tiles = tile_count(width, height, tile_size)
    packets_x = (width + packet - 1) // packet
    rays, work, _t, _b1, _b2, _prim, sub, sub_active, sub_done, sub_skip, mailbox = \
        packet_scratch(packet, sub_size)
    off_x, off_y = ray_offsets(sub_size)
    while True:
        tile = next_tile(queue, n_tiles)
        if tile < 0:
            break
        tx0, ty0 = tile_corner(tile, tiles_x, tile_size)
        for py in range(ty0, min(ty0 + tile_size, height), packet):
            for px in range(tx0, min(tx0 + tile_size, width), packet):
                pk = (py // packet) * packets_x + px // packet
                hit_t = sw_t[pk]
                hit_prim = sw_prim[pk]
                hit_b1 = sw_b1[pk]
                hit_b2 = sw_b2[pk]
                K, s, n_live, k_ref, w_end = setup_camera(
                    cam, px, py, packet, sub_size, width, height, jx, jy, off_x, off_y,
                    work, hit_t, hit_prim, sub, sub_active, grid.lo, grid.hi, eps)
                if K < 0:
                    camera_rays(rays, cam, px, py, packet, sub_size, width, height,
                                jx, jy, off_x, off_y)
                    dda_packet(rays, hit_t, hit_b1, hit_b2, hit_prim, False, grid, tri_verts,
                               counters, tile)
                elif n_live > 0:
                    walk(work, hit_t, hit_b1, hit_b2, hit_prim, False, True, K, s,
                         k_ref, w_end, sub, sub_done, sub_skip, mailbox, grid, tri_verts, eps,
                         counters, tile, cull)


@parallel_kernel
def trace_primary_on_threads(entry, ok, queue, cam, width, height, jx, jy, packet, sub_size, tile_size,
                             grid, tri_verts, eps, sw_t, sw_prim, sw_b1, sw_b2, counters, cull):
    """trace_primary on each of numba's threads (ok: a flag each, False if
    it failed), called through its native entry point (jit/launch.py: nothing
    linked in, nothing optimised twice)."""
    for w in prange(ok.shape[0]):
        ok[w] = call_native(entry, (queue, cam, width, height, jx, jy, packet, sub_size, tile_size, grid,
                                    tri_verts, eps, sw_t, sw_prim, sw_b1, sw_b2, counters, cull))


@helper
def load_packet(rays, pk, order, n_rays, ray_o, ray_d, t_min, t_max):
    """Rays order[pk * P:(pk + 1) * P] (P = the packet's ray count) into the
    packet's rows, from SoA (3, n) origins and directions; slots past n_rays
    are inactive (t_max = -1)."""
    n_sub = rays.shape[1]
    ss = rays.shape[2]
    per_packet = n_sub * ss
    for j in range(n_sub):
        for r in range(ss):
            s = pk * per_packet + j * ss + r
            i = order[min(s, n_rays - 1)]
            rays[OX, j, r] = ray_o[0, i]
            rays[OY, j, r] = ray_o[1, i]
            rays[OZ, j, r] = ray_o[2, i]
            rays[DX, j, r] = ray_d[0, i]
            rays[DY, j, r] = ray_d[1, i]
            rays[DZ, j, r] = ray_d[2, i]
            rays[TMIN, j, r] = t_min[i]
            rays[TMAX, j, r] = t_max[i] if s < n_rays else -F1


@kernel
def trace_ray_batch(order, n_rays, ray_o, ray_d, t_min, t_max, packet, sub_size, queue,
                    any_hit, shared_origin, grid, tri_verts, eps,
                    out_t, out_prim, out_b1, out_b2, out_vis, counters, cull):
    """Hits of rays order[0:n_rays], SoA (3, n) origins and directions, in
    packets of packet^2 consecutive entries of `order` (the caller orders
    them coherently: light-space order for shadow rays), those this thread
    pulls from `queue` (grid/trace.py starts one per thread,
    thread_pool.on_threads). Ray i's closest (any_hit: any) hit goes to
    out_*[i]; or, when out_vis is not empty (shadow rays), only out_vis[i] =
    1 for each unoccluded ray (the caller zeroes it). shared_origin: rays from one point.
    counters: (n_packets, N_COUNTERS) int64."""
    ss = sub_size * sub_size
    per_packet = packet * packet // ss * ss
    n_packets = (n_rays + per_packet - 1) // per_packet
    visibility = out_vis.shape[0] > 0
    rays, work, hit_t, hit_b1, hit_b2, hit_prim, sub, sub_active, sub_done, sub_skip, mailbox = \
        packet_scratch(packet, sub_size)
    while True:
        pk = next_tile(queue, n_packets)
        if pk < 0:
            break
        load_packet(rays, pk, order, n_rays, ray_o, ray_d, t_min, t_max)
        trace_or_fallback(rays, work, hit_t, hit_b1, hit_b2, hit_prim, any_hit, shared_origin,
                          sub, sub_active, sub_done, sub_skip, mailbox, grid, tri_verts, eps,
                          counters, pk, cull)
        for j in range(rays.shape[1]):
            for r in range(ss):
                s = pk * per_packet + j * ss + r
                if s < n_rays:
                    i = order[s]
                    if visibility:
                        if hit_prim[j, r] < 0:
                            out_vis[i] = F1
                    else:
                        out_t[i] = hit_t[j, r]
                        out_prim[i] = hit_prim[j, r]
                        out_b1[i] = hit_b1[j, r]
                        out_b2[i] = hit_b2[j, r]
