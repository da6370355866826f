"""Kd-tree traversal of camera packets: frustum packets in the style of the
multi-level ray tracing algorithm (MLRTA, Reshetov, Soupikov, Hurley 2005).
Single rays, the reference, are in kdtree/rays.py.

Camera packets share the eye and their unnormalised directions are affine in
the pixel position, so every per-axis quantity of the packet (direction
component, its inverse, slab entry and exit) takes its extremes at the four
corner rays. That gives:
* inverse frustum culling of a box (`frustum_misses_box`): project onto the
  planes of two axes; if even the smallest entry along one axis comes after
  the largest exit along the other (`min(b_entry) > max(a_exit)`), every ray
  misses. Two comparisons per axis pair, no false negatives;
* the frustum-cell decision at an inner node: visit each child whose box the
  frustum can touch, the one the rays reach first (sign of their common
  direction component) first;
* entry-point search: from the root, descend while the whole frustum of a
  tile needs only one child; each packet of the tile starts there;
* adaptive splitting: where the rays' direction signs differ along an axis,
  the corner-ray argument fails, so the frustum is split in four, down to
  single rays (which use the reference traversal).
Leaves test their triangles (after a frustum/box cull and a mailbox) against
every ray of the packet with one shear axis for the packet (the Woop test is
watertight along any axis the directions do not vanish on).
"""
import numpy as np

from raycore.jit.presets import helper, kernel
from raycore.geometry.camera import primary_dir_raw
from raycore.jit.counters import CANDIDATES, FALLBACK_RAYS, N_COUNTERS, PACKETS, TESTS, VISITS
from raycore.kdtree.build import LEAF, KdTree
from raycore.kdtree.rays import STACK, trace_one
from raycore.jit.thread_pool import on_threads
from raycore.jit.tile_queue import new_queue, next_tile, tile_corner, tile_count
from raycore.geometry.triangle import ray_axes, woop_test
from raycore.jit.floats import F0, F1, INF



@kernel
def frustum_of(cam, x0, y0, x1, y1, jx, jy, fr):
    """Fill fr (3, 4) with, per axis: min and max of the direction component
    and of its inverse over the corner rays of pixels x0..x1, y0..y1.
    Returns False when a component changes sign (or is zero) across them."""
    for a in range(3):
        fr[a, 0] = INF
        fr[a, 1] = -INF
    for c in range(4):
        x = x0 if (c & 1) == 0 else x1
        y = y0 if (c >> 1) == 0 else y1
        d = primary_dir_raw(cam, x, y, jx, jy)
        for a in range(3):
            fr[a, 0] = min(fr[a, 0], d[a])
            fr[a, 1] = max(fr[a, 1], d[a])
    for a in range(3):
        if not (fr[a, 0] > F0 or fr[a, 1] < F0):
            return False
        fr[a, 2] = F1 / fr[a, 1]          # the inverse is monotone (one sign)
        fr[a, 3] = F1 / fr[a, 0]
        if fr[a, 2] > fr[a, 3]:
            fr[a, 2], fr[a, 3] = fr[a, 3], fr[a, 2]
    return True


@helper
def _axis_entry_exit(o, fr, lo_a, hi_a, a):
    """(min entry, max exit) over the frustum's rays along axis a."""
    p = (lo_a - o[a]) * fr[a, 2]
    q = (lo_a - o[a]) * fr[a, 3]
    r = (hi_a - o[a]) * fr[a, 2]
    s = (hi_a - o[a]) * fr[a, 3]
    if fr[a, 0] > F0:          # rays run toward +a: enter at lo, leave at hi
        return min(p, q), max(r, s)
    return min(r, s), max(p, q)


@helper
def frustum_misses_box(o, fr, box, t_far):
    """True when no ray of the frustum (origin o, per-axis bounds fr) meets
    box (6,) before t_far: the projected 2D test on each pair of axes, plus
    the box lying behind the origin or beyond t_far. No false negatives."""
    e0, x0 = _axis_entry_exit(o, fr, box[0], box[3], 0)
    e1, x1 = _axis_entry_exit(o, fr, box[1], box[4], 1)
    e2, x2 = _axis_entry_exit(o, fr, box[2], box[5], 2)
    if e1 > x0 or e0 > x1 or e2 > x0 or e0 > x2 or e2 > x1 or e1 > x2:
        return True
    if x0 < F0 or x1 < F0 or x2 < F0:
        return True
    return max(e0, e1, e2) > t_far


@helper
def _child_box(box, a, sp, upper, out):
    for q in range(6):
        out[q] = box[q]
    if upper:
        out[a] = sp
    else:
        out[3 + a] = sp


@kernel
def entry_point(tree, o, fr, box, scratch):
    """Deepest node whose box contains the whole frustum's path through the
    tree (every ray that reaches a leaf reaches it through this node); its box
    is left in `box`. Returns (node, steps taken)."""
    lo, hi, tree_axis, tree_split, tree_child = tree.lo, tree.hi, tree.axis, tree.split, tree.child
    for q in range(3):
        box[q] = lo[q]
        box[3 + q] = hi[q]
    node = 0
    steps = 0
    while tree_axis[node] != LEAF:
        a = tree_axis[node]
        sp = tree_split[node]
        left = tree_child[node]
        _child_box(box, a, sp, False, scratch[0])
        _child_box(box, a, sp, True, scratch[1])
        miss_lo = frustum_misses_box(o, fr, scratch[0], INF)
        miss_hi = frustum_misses_box(o, fr, scratch[1], INF)
        if miss_lo and not miss_hi:
            node = left + 1
            for q in range(6):
                box[q] = scratch[1, q]
        elif miss_hi and not miss_lo:
            node = left
            for q in range(6):
                box[q] = scratch[0, q]
        else:
            break
        steps += 1
    return node, steps


@kernel
def frustum_walk(o, fr, n, ray_s, kx, ky, kz, t_lo, best_t, best_p, best_b1, best_b2,
                 ep, ep_box, tree, tri_verts,
                 stack_n, stack_box, scratch, mailbox, counters, row):
    """Walk n rays sharing origin o (frustum bounds fr, shear ray_s per ray on
    the common axes kx, ky, kz) through the tree from node ep (box ep_box),
    near child first; children outside the frustum, or beyond every ray's
    current end (best_t), are never visited. best_t holds each ray's t_max on
    entry (-inf: inactive).

    Shadow rays from a point light share their origin too, and were tried
    through this walk (8x8 blocks, frustum bounds from all 64 directions,
    any-hit): 2x slower than single rays on hand and toys and 23x on the
    runner, where blocks straddling a silhouette diverge. They use trace_one."""
    tree_axis, tree_split, tree_child, tree_count, refs = tree.axis, tree.split, tree.child, tree.count, tree.refs
    for m in range(mailbox.shape[0]):
        mailbox[m] = -1
    stack_n[0] = ep
    for q in range(6):
        stack_box[0, q] = ep_box[q]
    top = 1
    while top > 0:
        top -= 1
        node = stack_n[top]
        far_t = -INF
        for r in range(n):
            far_t = max(far_t, best_t[r])
        if frustum_misses_box(o, fr, stack_box[top], far_t):
            continue
        counters[row, VISITS] += 1
        if tree_axis[node] != LEAF:
            a = tree_axis[node]
            sp = tree_split[node]
            left = tree_child[node]
            below_first = fr[a, 0] > F0
            # push the far child first so the near one comes off the stack first
            for side in range(2):
                upper = (side == 0) if below_first else (side == 1)
                _child_box(stack_box[top], a, sp, upper, scratch[side])
            for side in range(2):
                upper = (side == 0) if below_first else (side == 1)
                stack_n[top] = left + 1 if upper else left
                for q in range(6):
                    stack_box[top, q] = scratch[side, q]
                top += 1
            continue
        counters[row, CANDIDATES] += 1
        first = tree_child[node]
        for k in range(first, first + tree_count[node]):
            tri = refs[k]
            m = tri & (mailbox.shape[0] - 1)
            if mailbox[m] == tri:
                continue
            mailbox[m] = tri
            for q in range(3):
                scratch[0, q] = min(tri_verts[tri, q], tri_verts[tri, 3 + q], tri_verts[tri, 6 + q])
                scratch[0, 3 + q] = max(tri_verts[tri, q], tri_verts[tri, 3 + q], tri_verts[tri, 6 + q])
            if frustum_misses_box(o, fr, scratch[0], far_t):
                continue
            ax = tri_verts[tri, kx] - o[kx]
            ay = tri_verts[tri, ky] - o[ky]
            az = tri_verts[tri, kz] - o[kz]
            bx = tri_verts[tri, 3 + kx] - o[kx]
            by = tri_verts[tri, 3 + ky] - o[ky]
            bz = tri_verts[tri, 3 + kz] - o[kz]
            cx = tri_verts[tri, 6 + kx] - o[kx]
            cy = tri_verts[tri, 6 + ky] - o[ky]
            cz = tri_verts[tri, 6 + kz] - o[kz]
            counters[row, TESTS] += n
            for r in range(n):
                hit, t, b1, b2 = woop_test(ax, ay, az, bx, by, bz, cx, cy, cz, ray_s[r, 0], ray_s[r, 1], ray_s[r, 2])
                better = hit & (t > t_lo[r]) & (t < best_t[r])
                best_t[r] = t if better else best_t[r]
                best_p[r] = tri if better else best_p[r]
                best_b1[r] = b1 if better else best_b1[r]
                best_b2[r] = b2 if better else best_b2[r]


@helper
def _shear(ray_d, n, kx, ky, kz, ray_s):
    for r in range(n):
        sz = F1 / ray_d[r, kz]
        ray_s[r, 0] = ray_d[r, kx] * sz
        ray_s[r, 1] = ray_d[r, ky] * sz
        ray_s[r, 2] = sz


@kernel
def _packet(cam, px, py, size, width, height, jx, jy, ep, ep_box, fr,
            tree, tri_verts,
            stack_n, stack_box, scratch, ray_d, ray_s, t_lo, best_t, best_p, best_b1, best_b2, mailbox,
            out_t, out_prim, out_b1, out_b2, counters, row):
    """Trace the size x size camera packet at (px, py) from node ep (box ep_box)."""
    counters[row, PACKETS] += 1
    o = (cam[0], cam[1], cam[2])
    n = np.int64(0)                 # not a literal 0 (jit/presets.py: "Literal arguments")
    for yy in range(size):
        for xx in range(size):
            d = primary_dir_raw(cam, px + xx, py + yy, jx, jy)
            ray_d[n, 0], ray_d[n, 1], ray_d[n, 2] = d[0], d[1], d[2]
            best_t[n] = INF if (px + xx < width and py + yy < height) else -INF
            best_p[n] = -1
            t_lo[n] = F0
            n += 1
    # one shear axis for the packet: the largest component at its centre
    dc = primary_dir_raw(cam, px + np.float32(size) * np.float32(0.5), py + np.float32(size) * np.float32(0.5), jx, jy)
    kx, ky, kz = ray_axes(dc[0], dc[1], dc[2])
    _shear(ray_d, n, kx, ky, kz, ray_s)
    frustum_walk(o, fr, n, ray_s, kx, ky, kz, t_lo, best_t, best_p, best_b1, best_b2,
                 ep, ep_box, tree, tri_verts,
                 stack_n, stack_box, scratch, mailbox, counters, row)
    r = 0
    for yy in range(size):
        for xx in range(size):
            x, y = px + xx, py + yy
            if x < width and y < height:
                i = y * width + x
                p = best_p[r]
                norm = np.sqrt(ray_d[r, 0] ** 2 + ray_d[r, 1] ** 2 + ray_d[r, 2] ** 2)
                out_t[i] = best_t[r] * norm if p >= 0 else INF
                out_prim[i] = p
                out_b1[i] = best_b1[r] if p >= 0 else F0
                out_b2[i] = best_b2[r] if p >= 0 else F0
            r += 1


@kernel
def trace_camera_kd(cam, width, height, jx, jy, packet, tile_size, queue, tree, tri_verts,
                    out_t, out_prim, out_b1, out_b2, counters):
    """Camera rays through the kd-tree: the tiles this thread pulls from
    `queue` (kd_trace_camera starts one per thread, thread_pool.on_threads);
    per tile an entry point, per packet a frustum walk from it, split where
    the corner-ray conditions fail (down to single rays)."""
    tiles_x, n_tiles = tile_count(width, height, tile_size)
    fr = np.empty((3, 4), np.float32)
    fr_tile = np.empty((3, 4), np.float32)
    ep_box = np.empty(6, np.float32)
    scratch = np.empty((2, 6), np.float32)
    stack_n = np.empty(STACK, np.int32)
    stack_box = np.empty((STACK, 6), np.float32)
    stack_t0 = np.empty(STACK, np.float32)
    stack_t1 = np.empty(STACK, np.float32)
    nn = packet * packet
    ray_d = np.empty((nn, 3), np.float32)
    ray_s = np.empty((nn, 3), np.float32)
    t_lo = np.empty(nn, np.float32)
    best_t = np.empty(nn, np.float32)
    best_p = np.empty(nn, np.int32)
    best_b1 = np.empty(nn, np.float32)
    best_b2 = np.empty(nn, np.float32)
    mailbox = np.empty(64, np.int32)
    todo = np.empty((64, 3), np.int64)      # pending (x, y, size) sub-frusta
    o = (cam[0], cam[1], cam[2])
    while True:
        tile = next_tile(queue, n_tiles)
        if tile < 0:
            break
        tx, ty = tile_corner(tile, tiles_x, tile_size)
        x1 = min(tx + tile_size, width) - 1
        y1 = min(ty + tile_size, height) - 1
        ep = 0
        for q in range(3):
            ep_box[q] = tree.lo[q]
            ep_box[3 + q] = tree.hi[q]
        if frustum_of(cam, tx, ty, x1 + 1, y1 + 1, F0, F0, fr_tile):
            ep, steps = entry_point(tree, o, fr_tile, ep_box, scratch)
            counters[tile, VISITS] += steps
        for py in range(ty, y1 + 1, packet):
            for px in range(tx, x1 + 1, packet):
                todo[0, 0], todo[0, 1], todo[0, 2] = px, py, packet
                n_todo = 1
                while n_todo > 0:
                    n_todo -= 1
                    x, y, size = todo[n_todo, 0], todo[n_todo, 1], todo[n_todo, 2]
                    if x >= width or y >= height:
                        continue
                    ok = frustum_of(cam, x, y, x + size, y + size, F0, F0, fr)
                    if ok and size > 1:
                        _packet(cam, x, y, size, width, height, jx, jy, ep, ep_box, fr,
                                tree, tri_verts,
                                stack_n, stack_box, scratch, ray_d, ray_s, t_lo, best_t, best_p,
                                best_b1, best_b2, mailbox, out_t, out_prim, out_b1, out_b2,
                                counters, tile)
                    elif size > 1:                      # adaptive split
                        h = size // 2
                        for c in range(4):
                            todo[n_todo, 0] = x + h * (c & 1)
                            todo[n_todo, 1] = y + h * (c >> 1)
                            todo[n_todo, 2] = h
                            n_todo += 1
                    else:                               # a single ray
                        d = primary_dir_raw(cam, x, y, jx, jy)
                        counters[tile, FALLBACK_RAYS] += 1
                        t, p, b1, b2 = trace_one(tree, tri_verts, o[0], o[1], o[2], d[0], d[1], d[2],
                                                 F0, INF, False, stack_n, stack_t0, stack_t1,
                                                 counters, tile)
                        norm = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
                        i = y * width + x
                        out_t[i] = t * norm if p >= 0 else INF
                        out_prim[i] = p
                        out_b1[i] = b1 if p >= 0 else F0
                        out_b2[i] = b2 if p >= 0 else F0


def kd_trace_camera(tree: KdTree, tri_verts, cam, width, height, packet=8, jitter=(0.5, 0.5), tile=32):
    """Row-major (t, prim, b1, b2, counters) of the camera rays: t along the
    unit ray, as the grid's trace_camera gives it."""
    import numba
    n = width * height
    out = (np.empty(n, np.float32), np.empty(n, np.int32), np.empty(n, np.float32), np.empty(n, np.float32))
    tile = max(tile, packet)
    n_tiles = -(-width // tile) * -(-height // tile)
    counters = np.zeros((n_tiles, N_COUNTERS), np.int64)
    on_threads(trace_camera_kd, numba.get_num_threads(), cam, width, height, np.float32(jitter[0]),
               np.float32(jitter[1]), packet, tile, new_queue(), tree, tri_verts, *out, counters)
    return (*out, counters.sum(axis=0))
