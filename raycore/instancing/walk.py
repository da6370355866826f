"""Packets of rays through an instanced world: the top level's tree over
the instances' world boxes, then, at each instance it reaches, the
prototype's tree in the instance's own space (bvh/packets.walk_packet,
unchanged), and the drivers that hand packets to the cores as bvh/trace.py
does for one tree.

A packet that reaches an instance is mapped by the instance's inverse
(origins and directions, not normalised: a ray's t is the same in both
spaces, so the closest hit so far bounds the walk in every instance). Rays
sharing an origin or a direction still share it after the map, so the
packet keeps its frustum inside; where the map leaves the packet without a
common shear axis its rays go one by one (bvh/packets.trace_single). The
top level's nodes are tested as the trees' inner nodes are, a 16-ray chunk
at a time, and a chunk that misses an instance's box skips it.
"""
import numpy as np

from raycore.bvh.nodes import CHILD, COUNT, STACK
from raycore.bvh.packets import (CHUNK_BITS, DX, DY, DZ, HINT_BITS, LANES, N_CHUNKS, NODE_SHIFT, OX, OY, OZ, PACKET,
                                 SHARED_DIRECTION, SHARED_ORIGIN, SINGLE, TMIN, N_ROWS, _chunks_hitting_box,
                                 _push_children, ray_hits_box, set_inverse, trace_single, walk_packet)
from raycore.bvh.trace import (load_batch_packet, load_camera_tile, load_light_packet, store_batch_packet,
                               store_camera_tile, store_light_vis)
from raycore.config import EPS_OFFSET_ULPS
from raycore.jit.counters import FALLBACK_RAYS, N_COUNTERS, PACKETS, VISITS
from raycore.jit.floats import F0, INF
from raycore.jit.presets import helper, kernel
from raycore.jit.thread_pool import on_threads
from raycore.jit.tile_queue import new_queue, next_tile


@helper
def _to_instance(ray, lray, idx, n, inverse, place_t, j):
    """Rays idx[0..n) of `ray` into instance j's space (a point p going to
    L^-1 (p - T): inverse[j]'s rows hold L^-1, place_t[j] T in float64),
    packed as rays 0..n-1 of `lray`."""
    m = inverse[j]
    tx, ty, tz = place_t[j, 0], place_t[j, 1], place_t[j, 2]
    for q in range(n):
        r = idx[q]
        ox = np.float32(np.float64(ray[OX, r]) - tx)
        oy = np.float32(np.float64(ray[OY, r]) - ty)
        oz = np.float32(np.float64(ray[OZ, r]) - tz)
        dx, dy, dz = ray[DX, r], ray[DY, r], ray[DZ, r]
        lray[OX, q] = m[0] * ox + m[1] * oy + m[2] * oz
        lray[OY, q] = m[4] * ox + m[5] * oy + m[6] * oz
        lray[OZ, q] = m[8] * ox + m[9] * oy + m[10] * oz
        lray[DX, q] = m[0] * dx + m[1] * dy + m[2] * dz
        lray[DY, q] = m[4] * dx + m[5] * dy + m[6] * dz
        lray[DZ, q] = m[8] * dx + m[9] * dy + m[10] * dz
        lray[TMIN, q] = ray[TMIN, r]


@helper
def _live(ray, h_t, n):
    live = 0
    for r in range(n):
        live += 1 if h_t[r] >= ray[TMIN, r] else 0
    return live


@helper
def _in_instance(trees, tree_root, lray, h_t, h_b1, h_b2, lprim, n, any_hit, vis_only, mode, ia, planes, stack,
                 counters, row):
    """Rays 0..n-1 (already in the instance's space) through the tree
    under tree_root: as a packet, or one by one."""
    for r in range(n):
        lprim[r] = -1
    if mode != SINGLE:
        set_inverse(lray, n)
        if walk_packet(trees, lray, h_t, h_b1, h_b2, lprim, n, any_hit, vis_only, mode, ia, planes, stack,
                       counters, row, tree_root):
            return
    for r in range(n):
        if not h_t[r] >= lray[TMIN, r]:
            continue
        t, k, b1, b2 = trace_single(trees, lray[OX, r], lray[OY, r], lray[OZ, r], lray[DX, r], lray[DY, r],
                                    lray[DZ, r], lray[TMIN, r], h_t[r], any_hit, stack, counters, row, tree_root)
        if k >= 0:
            h_t[r] = -INF if vis_only else t
            lprim[r], h_b1[r], h_b2[r] = k, b1, b2
        counters[row, FALLBACK_RAYS] += 1


@helper
def walk_world(top, trees, place_tree, inverse, place_t, ray, h_t, h_b1, h_b2, prim, inst, n, any_hit, vis_only, mode,
               local, ia, planes, stack, top_stack, counters, row):
    """Closest (or any) hits of packet rays 0..n-1 in an instanced world:
    on entry h_t holds each ray's t_max (-inf: no ray), prim -1; on return
    prim >= 0 marks a hit, prim the triangle (the frame's id) and inst the
    instance (place_tree[inst] its tree's root), as walk_packet's otherwise.
    At an instance, the rays that reach its box are packed into a packet
    of their own and carried into its space (local: that packet's
    buffers): a far instance seen by a few rays of a packet costs a walk
    of a few."""
    box, node_i, top_inst = top[0], top[1], top[2]
    lray, lt, lb1, lb2, lprim, idx, flag = local
    n_pad = min(PACKET, (n + LANES - 1) // LANES * LANES)
    for r in range(n, n_pad):                  # dead copies of ray 0 fill the last chunk
        for q in range(TMIN + 1):
            ray[q, r] = ray[q, 0]
        h_t[r] = -INF
    if _live(ray, h_t, n) == 0:
        return
    set_inverse(ray, n_pad)
    sx = F0
    sy = F0
    sz = F0
    for r in range(n):
        sx += ray[DX, r]
        sy += ray[DY, r]
        sz += ray[DZ, r]
    sgn = (sx >= F0, sy >= F0, sz >= F0)
    n_visits = 0
    top_stack[0] = (1 << ((n + LANES - 1) // LANES)) - 1       # the root, every chunk
    depth = 1
    while depth > 0:
        depth -= 1
        i = top_stack[depth] >> NODE_SHIFT
        mask = top_stack[depth] & ((1 << CHUNK_BITS) - 1)
        hint = (top_stack[depth] >> CHUNK_BITS) & ((1 << HINT_BITS) - 1)
        n_visits += 1
        c = node_i[i, COUNT]
        if c <= 0:
            mask, hint = _chunks_hitting_box(ray, h_t, mask, box, i, False, hint)
            if mask == 0:
                continue
            left = node_i[i, CHILD]
            if left < 0:
                continue
            depth = _push_children(top_stack, depth, left, sgn[-1 - c], mask, hint)
            continue
        # a leaf: its instances' box, ray by ray over the chunks that reached it
        m = 0
        x0, y0, z0 = box[i, 0], box[i, 1], box[i, 2]
        x1, y1, z1 = box[i, 3], box[i, 4], box[i, 5]
        for ch in range(N_CHUNKS):
            if (mask >> ch) & 1:
                c0 = ch * LANES
                # a chunk's box tests branch-free (one vector), then its hits packed
                for lane in range(LANES):
                    flag[lane] = ray_hits_box(ray, h_t, c0 + lane, x0, y0, z0, x1, y1, z1)
                for lane in range(LANES):
                    if flag[lane]:
                        idx[m] = c0 + lane
                        m += 1
        if m == 0:
            continue
        first = node_i[i, CHILD]
        for k in range(first, first + c):
            j = top_inst[k]
            _to_instance(ray, lray, idx, m, inverse, place_t, j)
            for q in range(m):
                lt[q] = h_t[idx[q]]
                lb1[q] = h_b1[idx[q]]
                lb2[q] = h_b2[idx[q]]
            _in_instance(trees, place_tree[j], lray, lt, lb1, lb2, lprim, m, any_hit, vis_only, mode, ia,
                         planes, stack, counters, row)
            for q in range(m):
                r = idx[q]
                h_t[r] = lt[q]
                if lprim[q] >= 0 and not vis_only:
                    prim[r] = trees[2][lprim[q]]
                    inst[r] = j
                    h_b1[r] = lb1[q]
                    h_b2[r] = lb2[q]
        if any_hit and _live(ray, h_t, n) == 0:
            break
    counters[row, VISITS] += n_visits


@helper
def world_scratch():
    """A packet's buffers: world rays and hits, the instance-space rays,
    the walks' stacks."""
    return (np.empty((N_ROWS, PACKET), np.float32), np.empty(PACKET, np.float32), np.empty(PACKET, np.float32),
            np.empty(PACKET, np.float32), np.empty(PACKET, np.int32), np.empty(PACKET, np.int32),
            (np.empty((N_ROWS, PACKET), np.float32), np.empty(PACKET, np.float32), np.empty(PACKET, np.float32),
             np.empty(PACKET, np.float32), np.empty(PACKET, np.int32), np.empty(PACKET, np.int64),
             np.empty(LANES, np.bool_)),
            np.empty((6, 3), np.float32), np.empty((6, 5), np.float32), np.empty(STACK, np.int64),
            np.empty(STACK, np.int64))


@kernel
def world_camera(top, trees, place_tree, inverse, place_t, cam, width, height, jx, jy, queue, out_t, out_prim, out_inst,
                 out_b1, out_b2, counters):
    """Closest hits of the camera rays (offset jx, jy), row-major, in
    8x8-pixel packets sharing the eye (bvh/trace.trace_camera_bvh's tiles)."""
    side = 8
    tiles_x = (width + side - 1) // side
    n_tiles = tiles_x * ((height + side - 1) // side)
    ray, h_t, h_b1, h_b2, prim, inst, local, ia, planes, stack, top_stack = world_scratch()
    while True:
        p = next_tile(queue, n_tiles)
        if p < 0:
            break
        x0 = (p % tiles_x) * side
        y0 = (p // tiles_x) * side
        n = load_camera_tile(ray, h_t, h_b1, h_b2, prim, cam, width, height, x0, y0, jx, jy, side)
        walk_world(top, trees, place_tree, inverse, place_t, ray, h_t, h_b1, h_b2, prim, inst, n, False, False,
                   SHARED_ORIGIN, local, ia, planes, stack, top_stack, counters, p)
        counters[p, PACKETS] += 1
        store_camera_tile(h_t, h_b1, h_b2, prim, inst, x0, y0, width, height, side, out_t, out_prim, out_inst,
                          out_b1, out_b2)


@kernel
def world_batch(top, trees, place_tree, inverse, place_t, order, n_active, origin, direction, t_min, t_max, any_hit, mode,
                queue, out_t, out_prim, out_inst, out_b1, out_b2, vis, counters):
    """Rays order[0..n_active) (origin, direction: (3, n) SoA) in packets
    of PACKET consecutive entries, as bvh/trace.trace_batch: hits (when
    out_t is not empty) or visibility (vis, when not empty: 1 = nothing in
    (t_min, t_max))."""
    n_packets = (n_active + PACKET - 1) // PACKET
    want_hits = out_t.shape[0] > 0
    want_vis = vis.shape[0] > 0
    vis_only = any_hit and want_vis and not want_hits
    ray, h_t, h_b1, h_b2, prim, inst, local, ia, planes, stack, top_stack = world_scratch()
    while True:
        p = next_tile(queue, n_packets)
        if p < 0:
            break
        base = p * PACKET
        n = min(PACKET, n_active - base)
        load_batch_packet(ray, h_t, h_b1, h_b2, prim, order, base, n, origin, direction, t_min, t_max,
                          mode == SHARED_ORIGIN)
        walk_world(top, trees, place_tree, inverse, place_t, ray, h_t, h_b1, h_b2, prim, inst, n, any_hit, vis_only,
                   mode, local, ia, planes, stack, top_stack, counters, p)
        counters[p, PACKETS] += 1
        store_batch_packet(h_t, h_b1, h_b2, prim, order, base, n, want_hits, want_vis, out_t, out_prim, out_b1,
                           out_b2, vis)
        if want_hits:
            for r in range(n):
                out_inst[order[base + r]] = inst[r] if prim[r] >= 0 else -1


@kernel
def world_light_samples(top, trees, place_tree, inverse, place_t, lights, rows, lifted, geo_n, smooth_n, mag, offset_ulps,
                        skip, queue, vis, counters):
    """bvh/trace.trace_light_samples in an instanced world: every light's
    shadow rays from the samples of the packets this thread pulls, into
    vis[rows[j]]. Returns how many rays were active."""
    ray, h_t, h_b1, h_b2, prim, inst, local, ia, planes, stack, top_stack = world_scratch()
    n_samples = mag.shape[0]
    n_packets = (n_samples + PACKET - 1) // PACKET
    live = 0
    while True:
        p = next_tile(queue, n_packets)
        if p < 0:
            break
        base = p * PACKET
        n = min(PACKET, n_samples - base)
        for j in range(rows.shape[0]):
            active, mode = load_light_packet(ray, h_t, h_b1, h_b2, prim, n, base, lights, j, lifted, geo_n,
                                             smooth_n, mag, offset_ulps, skip)
            live += active
            walk_world(top, trees, place_tree, inverse, place_t, ray, h_t, h_b1, h_b2, prim, inst, n, True, True, mode,
                       local, ia, planes, stack, top_stack, counters, p)
            counters[p, PACKETS] += 1
            store_light_vis(vis, rows[j], base, n, ray, h_t)
    return live


# --- plain-Python wrappers ---------------------------------------------------
def _workers():
    import numba
    return numba.get_num_threads()


def _counters(n_rays):
    return np.zeros((max(1, -(-n_rays // PACKET)), N_COUNTERS), np.int64)


NO_HITS = (np.zeros(0, np.float32), np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(0, np.float32),
           np.zeros(0, np.float32))
NO_SKIP = np.zeros(0, np.bool_)


def world_trace_camera(world, cam, width, height, jitter, out):
    """Row-major (t, prim, inst, b1, b2) of one camera ray per pixel into
    out, and the counters. world: (top, trees, place_tree, inverse, place_t)."""
    counters = np.zeros((-(-width // 8) * -(-height // 8), N_COUNTERS), np.int64)
    on_threads(world_camera, _workers(), *world, cam, width, height, np.float32(jitter[0]), np.float32(jitter[1]),
               new_queue(), *out, counters)
    return counters.sum(axis=0)


def world_trace_rays(world, origins, dirs, t_min=None, t_max=None, any_hit=False, mode=None):
    """(t, prim, inst, b1, b2, counters) of rays (n, 3), packets in the
    given order (mode as bvh/trace.bvh_trace_rays chooses it)."""
    from raycore.bvh.trace import ray_mode
    origins = np.asarray(origins, np.float32)
    dirs = np.asarray(dirs, np.float32)
    n = origins.shape[0]
    mode = ray_mode(origins, dirs) if mode is None else mode
    t_min = np.zeros(n, np.float32) if t_min is None else np.ascontiguousarray(t_min, np.float32)
    t_max = np.full(n, np.inf, np.float32) if t_max is None else np.ascontiguousarray(t_max, np.float32)
    out = (np.empty(n, np.float32), np.empty(n, np.int32), np.empty(n, np.int32), np.empty(n, np.float32),
           np.empty(n, np.float32))
    counters = _counters(n)
    on_threads(world_batch, _workers(), *world, np.arange(n, dtype=np.int32), n, np.ascontiguousarray(origins.T), np.ascontiguousarray(dirs.T),
               t_min, t_max, any_hit, mode, new_queue(), *out, np.zeros(0, np.float32), counters)
    return (*out, counters.sum(axis=0))


def world_light_visibility(world, rays, vis):
    """Visibility of one light's shadow rays (geometry/light_rays.LightRays,
    in light-space order) in packets sharing the light."""
    vis[:] = 0.0
    counters = _counters(rays.n_active)
    mode = SHARED_ORIGIN if rays.shared_origin else SHARED_DIRECTION
    on_threads(world_batch, _workers(), *world, rays.order, rays.n_active, rays.origin, rays.direction, rays.t_min,
               rays.t_max, True, mode, new_queue(), *NO_HITS, vis, counters)
    return counters.sum(axis=0)


def world_sample_visibility(world, surface, lights, rows, vis, skip=None):
    """(active rays, counters): lights (m, 4) seen from every sample of a
    Surface into vis[rows[j]] (bvh/trace.bvh_sample_visibility's rays)."""
    n = surface.mag.shape[0]
    counters = _counters(n)
    skip = NO_SKIP if skip is None else np.ascontiguousarray(skip, np.bool_)
    live = on_threads(world_light_samples, _workers(), *world, np.ascontiguousarray(lights, np.float32),
                      np.asarray(rows, np.int64), surface.lifted, surface.geo_n, surface.smooth_n, surface.mag,
                      np.float32(EPS_OFFSET_ULPS), skip, new_queue(), vis, counters)
    return int(sum(live)), counters.sum(axis=0)
