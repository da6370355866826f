"""BVH traversal drivers: packets of rays pulled from the tile queue by one
worker per thread (shadow rays in light-space order, batches of rays,
camera tiles of 8x8 pixels), each traced by bvh/packets.walk_packet, or ray
by ray where a packet has no common shear axis; and the plain-Python
wrappers the accelerator surface calls (accelerators.BvhAccel)."""
import numpy as np

from raycore.jit.presets import flat_kernel, helper, kernel
from raycore.bvh.nodes import STACK, Bvh
from raycore.bvh.packets import (DX, DY, DZ, N_ROWS, OX, OY, OZ, PACKET, SHARED_DIRECTION,
                                 SHARED_ORIGIN, SINGLE, TMIN, set_inverse, trace_single, walk_packet)
from raycore.geometry.camera import primary_dir
from raycore.config import EPS_OFFSET_ULPS, SHADOW_T_MIN_FRACTION
from raycore.jit.counters import FALLBACK_RAYS, N_COUNTERS, PACKETS
from raycore.geometry.light_rays import directional_light_ray, point_light_ray
from raycore.jit.thread_pool import on_threads
from raycore.jit.tile_queue import new_queue, next_tile
from raycore.jit.floats import F0, F1, INF

__all__ = ["PACKET", "SHARED_DIRECTION", "SHARED_ORIGIN", "SINGLE", "bvh_light_visibility",
           "bvh_sample_visibility", "bvh_trace_camera", "bvh_trace_rays", "scratch", "trace_batch",
           "trace_block_lights_into", "trace_camera_bvh", "trace_light_samples"]


NO_SKIP = np.zeros(0, np.bool_)


@helper
def _trace_packet(bvh, ray, h_t, h_b1, h_b2, prim, n, any_hit, vis_only, mode, ia, planes, stack, counters,
                  row):
    """Packet rays 0..n-1 as walk_packet, or one by one when they have no
    common shear axis (or mode is SINGLE)."""
    if mode != SINGLE:
        set_inverse(ray, n)
        if walk_packet(bvh, ray, h_t, h_b1, h_b2, prim, n, any_hit, vis_only, mode, ia, planes, stack,
                       counters, row, np.int64(0)):
            return
    for r in range(n):
        if not h_t[r] >= ray[TMIN, r]:
            continue
        t, k, b1, b2 = trace_single(bvh, ray[OX, r], ray[OY, r], ray[OZ, r], ray[DX, r], ray[DY, r],
                                    ray[DZ, r], ray[TMIN, r], h_t[r], any_hit, stack, counters, row, np.int64(0))
        h_t[r], prim[r], h_b1[r], h_b2[r] = (-INF if (vis_only and k >= 0) else t), k, b1, b2
        counters[row, FALLBACK_RAYS] += 1
    counters[row, PACKETS] += 1


@helper
def scratch():
    return (np.empty((N_ROWS, PACKET), np.float32), np.empty(PACKET, np.float32), np.empty(PACKET, np.float32),
            np.empty(PACKET, np.float32), np.empty(PACKET, np.int32), np.empty((6, 3), np.float32),
            np.empty((6, 5), np.float32), np.empty(STACK, np.int64))


@helper
def load_batch_packet(ray, h_t, h_b1, h_b2, prim, order, base, n, origin, direction, t_min, t_max, shared):
    """Rays order[base..base+n) of a batch (origin, direction: (3, n) SoA)
    into a packet; shared: every ray starts at the first one's origin (not
    gathered ray by ray)."""
    i0 = order[base]
    for r in range(n):
        i = order[base + r]
        j = i0 if shared else i
        ray[OX, r], ray[OY, r], ray[OZ, r] = origin[0, j], origin[1, j], origin[2, j]
        ray[DX, r], ray[DY, r], ray[DZ, r] = direction[0, i], direction[1, i], direction[2, i]
        ray[TMIN, r] = t_min[i]
        h_t[r] = t_max[i]
        h_b1[r] = F0
        h_b2[r] = F0
        prim[r] = -1


@helper
def store_batch_packet(h_t, h_b1, h_b2, prim, order, base, n, want_hits, want_vis, out_t, out_prim, out_b1,
                       out_b2, vis):
    """A packet's results back to rays order[base..base+n): hits (prim: the
    triangle ids, -1 none) and/or visibility (a loaded ray is live, t_max >=
    t_min: -inf means occluded)."""
    for r in range(n):
        i = order[base + r]
        k = prim[r]
        if want_vis:
            vis[i] = F0 if (k >= 0 or h_t[r] == -INF) else F1
        if want_hits:
            out_prim[i] = k
            out_t[i] = h_t[r] if k >= 0 else INF
            out_b1[i] = h_b1[r]
            out_b2[i] = h_b2[r]


@kernel
def trace_batch(bvh, order, n_active, origin, direction, t_min, t_max, any_hit, mode, queue, out_t, out_prim,
                out_b1, out_b2, vis, counters):
    """Rays order[0..n_active) (origin, direction: (3, n) SoA) in packets of
    PACKET consecutive entries, those this thread pulls from `queue` until
    none are left (the wrappers below start one per thread,
    thread_pool.on_threads). Writes the hits (out_*, global triangle ids,
    when out_t is not empty) or the visibility (vis, when not empty: 1 =
    nothing in (t_min, t_max)). mode SINGLE traces every ray alone.
    counters: one row per packet."""
    n_packets = (n_active + PACKET - 1) // PACKET
    want_hits = out_t.shape[0] > 0
    want_vis = vis.shape[0] > 0
    vis_only = any_hit and want_vis and not want_hits
    ray, h_t, h_b1, h_b2, prim, ia, planes, stack = scratch()
    while True:
        p = next_tile(queue, n_packets)
        if p < 0:
            break
        base = p * PACKET
        n = min(PACKET, n_active - base)
        load_batch_packet(ray, h_t, h_b1, h_b2, prim, order, base, n, origin, direction, t_min, t_max,
                          mode == SHARED_ORIGIN)
        _trace_packet(bvh, ray, h_t, h_b1, h_b2, prim, n, any_hit, vis_only, mode, ia, planes, stack,
                      counters, p)
        if want_hits:
            for r in range(n):
                prim[r] = bvh.tri[prim[r]] if prim[r] >= 0 else -1
        store_batch_packet(h_t, h_b1, h_b2, prim, order, base, n, want_hits, want_vis, out_t, out_prim, out_b1,
                           out_b2, vis)


@helper
def load_light_packet(ray, h_t, h_b1, h_b2, prim, n, base, lights, j, lifted, geo_n, smooth_n, mag, offset_ulps,
                      skip):
    """Samples base..base+n-1's shadow rays to light j (lights: kind, x, y,
    z) into a packet, made here from the samples (the same rays
    geometry/light_rays.light_rays makes); inactive ones dead. Returns
    (how many are active, the packet's mode: the rays share the point
    light as origin, or the directional light's direction)."""
    kind = int(lights[j, 0])
    lx, ly, lz = lights[j, 1], lights[j, 2], lights[j, 3]
    light_mag = max(abs(lx), max(abs(ly), abs(lz)))
    live = 0
    if kind == 0:
        for r in range(n):
            dx, dy, dz, dist, t_far = point_light_ray(lx, ly, lz, light_mag, lifted, geo_n, smooth_n, mag,
                                                      offset_ulps, np.uint64(base + r))
            ray[OX, r], ray[OY, r], ray[OZ, r] = lx, ly, lz
            ray[DX, r], ray[DY, r], ray[DZ, r] = dx, dy, dz
            ray[TMIN, r] = dist * SHADOW_T_MIN_FRACTION
            h_t[r] = t_far
            live += 1 if t_far > F0 else 0
    else:
        for r in range(n):
            ox, oy, oz, t_far = directional_light_ray(lx, ly, lz, lifted, geo_n, smooth_n, mag, offset_ulps,
                                                      np.uint64(base + r))
            ray[OX, r], ray[OY, r], ray[OZ, r] = ox, oy, oz
            ray[DX, r], ray[DY, r], ray[DZ, r] = -lx, -ly, -lz
            ray[TMIN, r] = F0
            h_t[r] = t_far
            live += 1 if t_far > F0 else 0
    if skip.shape[0] > 0:
        for r in range(n):
            if skip[np.uint64(base + r)] and h_t[r] > F0:
                h_t[r] = -F1
                live -= 1
    for r in range(n):
        h_b1[r] = F0
        h_b2[r] = F0
        prim[r] = -1
    return live, SHARED_ORIGIN if kind == 0 else SHARED_DIRECTION


@helper
def store_light_vis(vis, out, base, n, ray, h_t):
    """A light packet's visibility into vis[out, base..base+n-1]: lit where
    the ray is active (t_max >= t_min, which an inactive ray's -1 is not)
    and not occluded (-inf)."""
    for r in range(n):
        vis[out, np.uint64(base + r)] = F1 if h_t[r] >= ray[TMIN, r] else F0


@helper
def _light_packet(bvh, lights, rows, base, n, lifted, geo_n, smooth_n, mag, offset_ulps, skip, vis, counters,
                  row, ray, h_t, h_b1, h_b2, prim, ia, planes, stack):
    """Samples base..base+n-1 (one packet): their shadow rays to every light
    in turn, while the samples are in cache, into vis[rows[j]]. Returns how
    many rays were active."""
    live = 0
    for j in range(rows.shape[0]):
        active, mode = load_light_packet(ray, h_t, h_b1, h_b2, prim, n, base, lights, j, lifted, geo_n, smooth_n,
                                         mag, offset_ulps, skip)
        live += active
        _trace_packet(bvh, ray, h_t, h_b1, h_b2, prim, n, True, True, mode, ia, planes, stack, counters, row)
        store_light_vis(vis, rows[j], base, n, ray, h_t)
    return live


@kernel
def trace_light_samples(bvh, lights, rows, lifted, geo_n, smooth_n, mag, offset_ulps, skip, queue, vis,
                        counters):
    """Visibility of lights (m, 4) (kind 0: point at (x, y, z); 1:
    directional along it) from the surface samples of the packets this
    thread pulls from `queue` (bvh_sample_visibility starts one per
    thread): vis[rows[j], i] = 1 when sample i's shadow ray reaches light
    j, 0 when it is occluded, faces away or skip[i] (when skip is not
    empty). The rays are made in the packets, PACKET consecutive samples
    each (a camera pass's samples come in 32x32-pixel blocks, so a packet's
    are neighbours), instead of being written out by light_rays and read
    back: 44 bytes a sample moved per light instead of ~120, and no sort; a
    packet's samples serve every light while they are in cache. Returns how
    many rays were active. counters: one row per packet."""
    ray, h_t, h_b1, h_b2, prim, ia, planes, stack = scratch()
    n_samples = mag.shape[0]
    n_packets = (n_samples + PACKET - 1) // PACKET
    live = 0
    while True:
        p = next_tile(queue, n_packets)
        if p < 0:
            break
        base = p * PACKET
        live += _light_packet(bvh, lights, rows, base, min(PACKET, n_samples - base), lifted, geo_n, smooth_n,
                              mag, offset_ulps, skip, vis, counters, p, ray, h_t, h_b1, h_b2, prim, ia, planes,
                              stack)
    return live


@flat_kernel
def trace_block_lights_into(bvh, lights, rows, n, lifted, geo_n, smooth_n, mag, offset_ulps, vis, counters, row,
                            ray, h_t, h_b1, h_b2, prim, ia, planes, stack, live):
    """trace_light_samples for one block's samples 0..n-1 (buffers of
    the sweep, which stay in cache), on the calling thread, in packets
    of PACKET; counters row `row`; the active rays are added to live[0].
    The sweep calls it through its machine-code address (launch.call_native:
    no result), so that the packet walk is compiled on its own, and only
    when a frame has shadow rays, not linked into every sweep."""
    for base in range(0, n, PACKET):
        live[0] += _light_packet(bvh, lights, rows, base, min(PACKET, n - base), lifted, geo_n, smooth_n, mag,
                                 offset_ulps, NO_SKIP, vis, counters, row, ray, h_t, h_b1, h_b2, prim, ia, planes,
                                 stack)


_BLOCK_BUFFERS = []     # stand-ins for the sweep's own buffers, made once


def block_lights_entry(bvh, lights, rows, counters) -> int:
    """The address of trace_block_lights_into compiled for the buffers
    sweep.shade_blocks calls it with (GATHER_BLOCK^2 samples, scratch()'s
    packet buffers, int64 scalars). Those buffers' stand-ins are made once:
    only their kinds count (launch.value_kind), not their sizes."""
    from raycore.jit.launch import native_entry
    if not _BLOCK_BUFFERS:
        from raycore.config import GATHER_BLOCK
        m = GATHER_BLOCK * GATHER_BLOCK
        rows3 = np.empty((3, m), np.float32)
        _BLOCK_BUFFERS.extend((rows3, np.empty(m, np.float32), np.empty((1, m), np.float32), scratch.py_func(),
                               np.zeros(1, np.int64)))
    rows3, mag, vis, packet, live = _BLOCK_BUFFERS
    return native_entry(trace_block_lights_into, bvh, lights, rows, np.int64(0), rows3, rows3, rows3, mag,
                        np.float32(0), vis, counters, np.int64(0), *packet, live)


@helper
def load_camera_tile(ray, h_t, h_b1, h_b2, prim, cam, width, height, x0, y0, jx, jy, side):
    """The camera rays of the side x side pixels from (x0, y0) into a
    packet, row by row; pixels past the image's edge repeat the last
    column or row as dead rays. Returns the packet's size."""
    n = np.int64(0)             # not a literal 0 (jit/presets.py: "Literal arguments")
    for yy in range(side):
        for xx in range(side):
            x = min(x0 + xx, width - 1)
            y = min(y0 + yy, height - 1)
            d = primary_dir(cam, x, y, jx, jy)
            ray[OX, n], ray[OY, n], ray[OZ, n] = cam[0], cam[1], cam[2]
            ray[DX, n], ray[DY, n], ray[DZ, n] = d[0], d[1], d[2]
            ray[TMIN, n] = F0
            # pixels past the image's edge repeat the last column/row: dead rays
            h_t[n] = INF if (x0 + xx < width and y0 + yy < height) else -INF
            h_b1[n] = F0
            h_b2[n] = F0
            prim[n] = -1
            n += 1
    return n


@helper
def store_camera_tile(h_t, h_b1, h_b2, prim, inst, x0, y0, width, height, side, out_t, out_prim, out_inst, out_b1,
                      out_b2):
    """A camera tile's hits (load_camera_tile's order; prim: the triangle
    ids, -1 none) into the row-major images, and each hit's instance
    (inst) where out_inst is not empty (an instanced world's)."""
    with_inst = out_inst.shape[0] > 0
    q = 0
    for yy in range(side):
        for xx in range(side):
            x = x0 + xx
            y = y0 + yy
            if x < width and y < height:
                i = y * width + x
                hit = prim[q] >= 0
                out_prim[i] = prim[q]
                out_t[i] = h_t[q] if hit else INF
                out_b1[i] = h_b1[q]
                out_b2[i] = h_b2[q]
                if with_inst:
                    out_inst[i] = inst[q] if hit else -1
            q += 1


@kernel
def trace_camera_bvh(bvh, cam, width, height, jx, jy, queue, out_t, out_prim, out_b1, out_b2, counters):
    """Closest hits of the camera rays (offset jx, jy), row-major: the
    8x8-pixel packets sharing the eye that this thread pulls from `queue`
    (bvh_trace_camera starts one per thread, thread_pool.on_threads)."""
    side = 8
    tiles_x = (width + side - 1) // side
    n_tiles = tiles_x * ((height + side - 1) // side)
    ray, h_t, h_b1, h_b2, prim, ia, planes, stack = scratch()
    no_inst = np.empty(0, np.int32)            # hits without instances (store_camera_tile)
    while True:
        p = next_tile(queue, n_tiles)
        if p < 0:
            break
        x0 = (p % tiles_x) * side
        y0 = (p // tiles_x) * side
        n = load_camera_tile(ray, h_t, h_b1, h_b2, prim, cam, width, height, x0, y0, jx, jy, side)
        _trace_packet(bvh, ray, h_t, h_b1, h_b2, prim, n, False, False, SHARED_ORIGIN, ia, planes, stack,
                      counters, p)
        for r in range(n):
            prim[r] = bvh.tri[prim[r]] if prim[r] >= 0 else -1
        store_camera_tile(h_t, h_b1, h_b2, prim, prim, x0, y0, width, height, side, out_t, out_prim, no_inst,
                          out_b1, out_b2)


# --- plain-Python wrappers: validate, allocate, call ------------------------
NO_HITS = (np.zeros(0, np.float32), np.zeros(0, np.int32), np.zeros(0, np.float32), np.zeros(0, np.float32))


def _workers():
    import numba
    return numba.get_num_threads()


def _counters(n_rays):
    return np.zeros((max(1, -(-n_rays // PACKET)), N_COUNTERS), np.int64)


def bvh_light_visibility(bvh: Bvh, rays, vis):
    """Visibility (1 lit, 0 shadowed or facing away) of one light's shadow
    rays (geometry/light_rays.LightRays, in light-space order): packets sharing the
    light as origin (point light) or its direction (directional light)."""
    vis[:] = 0.0
    counters = _counters(rays.n_active)
    mode = SHARED_ORIGIN if rays.shared_origin else SHARED_DIRECTION
    on_threads(trace_batch, _workers(), bvh, rays.order, rays.n_active, rays.origin, rays.direction, rays.t_min,
               rays.t_max, True, mode, new_queue(), *NO_HITS, vis, counters)
    return vis, counters.sum(axis=0)


def bvh_sample_visibility(bvh: Bvh, surface, lights, rows, vis, skip=None):
    """Visibility (1 lit, 0 shadowed or facing away) of lights (m, 4) (the
    light table's kind, x, y, z) from every sample of a camera pass's
    Surface into vis[rows[j]], their shadow rays made and traced in the
    samples' order (trace_light_samples), and (active rays, counters)."""
    n = surface.mag.shape[0]
    counters = _counters(n)
    skip = NO_SKIP if skip is None else np.ascontiguousarray(skip, np.bool_)
    live = on_threads(trace_light_samples, _workers(), bvh, np.ascontiguousarray(lights, np.float32),
                      np.asarray(rows, np.int64), surface.lifted, surface.geo_n, surface.smooth_n, surface.mag,
                      np.float32(EPS_OFFSET_ULPS), skip, new_queue(), vis, counters)
    return int(sum(live)), counters.sum(axis=0)


def ray_mode(origins, dirs):
    """SHARED_ORIGIN when rays (n, 3) share their origin, SHARED_DIRECTION
    their direction, else SINGLE."""
    n = origins.shape[0]
    if n and np.all(origins == origins[:1]):
        return SHARED_ORIGIN
    if n and np.all(dirs == dirs[:1]):
        return SHARED_DIRECTION
    return SINGLE


def bvh_trace_rays(bvh: Bvh, origins, dirs, t_min=None, t_max=None, any_hit=False, mode=None):
    """(t, prim, b1, b2, counters) of arbitrary rays (n, 3): packets when all
    rays share their origin or their direction, else one ray at a time
    (mode SINGLE forces that)."""
    origins = np.asarray(origins, np.float32)
    dirs = np.asarray(dirs, np.float32)
    n = origins.shape[0]
    if mode is None:
        mode = ray_mode(origins, dirs)
    t_min = np.zeros(n, np.float32) if t_min is None else np.ascontiguousarray(t_min, np.float32)
    t_max = np.full(n, np.inf, np.float32) if t_max is None else np.ascontiguousarray(t_max, np.float32)
    out = (np.empty(n, np.float32), np.empty(n, np.int32), np.empty(n, np.float32), np.empty(n, np.float32))
    counters = _counters(n)
    on_threads(trace_batch, _workers(), bvh, np.arange(n, dtype=np.int32), n, np.ascontiguousarray(origins.T),
               np.ascontiguousarray(dirs.T), t_min, t_max, any_hit, mode, new_queue(), *out, np.zeros(0, np.float32),
               counters)
    return (*out, counters.sum(axis=0))


def bvh_trace_camera(bvh: Bvh, cam, width, height, jitter=(0.5, 0.5), out=None):
    """Row-major (t, prim, b1, b2, counters) of one camera ray per pixel."""
    n = width * height
    if out is None:
        out = (np.empty(n, np.float32), np.empty(n, np.int32), np.empty(n, np.float32), np.empty(n, np.float32))
    n_tiles = -(-width // 8) * -(-height // 8)
    counters = np.zeros((n_tiles, N_COUNTERS), np.int64)
    on_threads(trace_camera_bvh, _workers(), bvh, cam, width, height, np.float32(jitter[0]),
               np.float32(jitter[1]), new_queue(), *out, counters)
    return (*out, counters.sum(axis=0))
