"""Kd-tree traversal of single rays: the reference every kd-tree packet is
checked against, and the kd-tree's shadow rays and ray batches (one any-hit
or closest-hit ray at a time, chunks of rays pulled from the tile queue).

Near child first with a stack of far children and their t-intervals; a
split plane's t is widened by EPS_KD_SPLIT_REL (config.py) so that a ray
through a split plane never falls between the two children.
"""
import numpy as np

from raycore.jit.presets import helper, kernel
from raycore.config import EPS_KD_SPLIT_REL
from raycore.jit.counters import CANDIDATES, N_COUNTERS, TESTS, VISITS
from raycore.kdtree.build import LEAF, KdTree
from raycore.jit.thread_pool import on_threads
from raycore.jit.tile_queue import new_queue, next_tile
from raycore.geometry.triangle import ray_axes, sheared_test
from raycore.jit.floats import F0, F1, INF

STACK = 128
KD_RAY_CHUNK = 1024            # rays per chunk of trace_kd_rays' queue


@helper
def _slab(o, d, lo, hi, t0, t1):
    """Parametric interval of ray (o, d) inside box [lo, hi], clipped to [t0, t1]."""
    for a in range(3):
        if d[a] == F0:
            if o[a] < lo[a] or o[a] > hi[a]:
                return F1, F0
            continue
        inv = F1 / d[a]
        ta = (lo[a] - o[a]) * inv
        tb = (hi[a] - o[a]) * inv
        if ta > tb:
            ta, tb = tb, ta
        t0 = max(t0, ta)
        t1 = min(t1, tb)
    return t0, t1


@kernel
def trace_one(tree, tri_verts,
              ox, oy, oz, dx, dy, dz, t_min, t_max, any_hit, stack_n, stack_t0, stack_t1, counters, row):
    """Closest (or any) hit of one ray in `tree` (kdtree/build.KdTree):
    (t, prim, b1, b2); prim -1 = none in (t_min, t_max)."""
    lo, hi, tree_axis, tree_split, tree_child, tree_count, refs, _depth = tree
    o = (ox, oy, oz)
    d = (dx, dy, dz)
    best_t, best_p, best_b1, best_b2 = t_max, -1, F0, F0
    t0, t1 = _slab(o, d, lo, hi, t_min, t_max)
    if not t0 <= t1:
        return best_t, best_p, best_b1, best_b2
    kx, ky, kz = ray_axes(dx, dy, dz)
    sz = F1 / d[kz]
    sx = d[kx] * sz
    sy = d[ky] * sz
    node = 0
    top = 0
    while True:
        while tree_axis[node] != LEAF:
            counters[row, VISITS] += 1
            a = tree_axis[node]
            sp = tree_split[node]
            left = tree_child[node]
            if o[a] < sp or (o[a] == sp and d[a] <= F0):
                near, far = left, left + 1
            else:
                near, far = left + 1, left
            if d[a] == F0:
                node = near
                continue
            t = (sp - o[a]) / d[a]
            tol = EPS_KD_SPLIT_REL * (abs(t0) + abs(t1))
            if t <= F0 or t > t1 + tol:
                node = near
            elif t < t0 - tol:
                node = far
            else:
                stack_n[top] = far
                stack_t0[top] = max(t0, t - tol)
                stack_t1[top] = t1
                top += 1
                node = near
                t1 = min(t1, t + tol)
        counters[row, VISITS] += 1
        counters[row, CANDIDATES] += 1
        first = tree_child[node]
        for k in range(first, first + tree_count[node]):
            tri = refs[k]
            counters[row, TESTS] += 1
            hit, t, b1, b2 = sheared_test(tri_verts, tri, o, kx, ky, kz, sx, sy, sz)
            if hit and t > t_min and t < best_t:
                best_t, best_p, best_b1, best_b2 = t, tri, b1, b2
                if any_hit:
                    return best_t, best_p, best_b1, best_b2
        # skip stacked nodes that start beyond the best hit so far
        while True:
            if top == 0:
                return best_t, best_p, best_b1, best_b2
            top -= 1
            if best_t >= stack_t0[top]:
                node, t0, t1 = stack_n[top], stack_t0[top], stack_t1[top]
                break


@kernel
def trace_kd_rays(tree, tri_verts, origins, dirs, t_min, t_max, any_hit, chunk, queue,
                  out_t, out_prim, out_b1, out_b2, counters):
    """Single-ray traversal of arbitrary rays (the reference), in chunks of
    `chunk` consecutive rays this thread pulls from `queue` (one worker per
    thread, thread_pool.on_threads; a chunk of rays
    that all miss costs little, one in a crowded corner much more: a static
    split would leave a thread idle). counters: one row per chunk."""
    n = origins.shape[0]
    n_chunks = (n + chunk - 1) // chunk
    stack_n = np.empty(STACK, np.int32)
    stack_t0 = np.empty(STACK, np.float32)
    stack_t1 = np.empty(STACK, np.float32)
    while True:
        c = next_tile(queue, n_chunks)
        if c < 0:
            break
        for i in range(c * chunk, min((c + 1) * chunk, n)):
            t, p, b1, b2 = trace_one(tree, tri_verts, origins[i, 0], origins[i, 1], origins[i, 2],
                                     dirs[i, 0], dirs[i, 1], dirs[i, 2], t_min[i], t_max[i],
                                     any_hit, stack_n, stack_t0, stack_t1, counters, c)
            out_t[i] = t if p >= 0 else INF
            out_prim[i] = p
            out_b1[i] = b1
            out_b2[i] = b2


def kd_trace_rays(tree: KdTree, tri_verts, origins, dirs, t_min=None, t_max=None, any_hit=False):
    """(t, prim, b1, b2, counters) of arbitrary rays by single-ray traversal."""
    import numba
    origins = np.ascontiguousarray(origins, np.float32)
    dirs = np.ascontiguousarray(dirs, np.float32)
    n = len(origins)
    t_min = np.zeros(n, np.float32) if t_min is None else np.ascontiguousarray(t_min, np.float32)
    t_max = np.full(n, np.inf, np.float32) if t_max is None else np.ascontiguousarray(t_max, np.float32)
    out = (np.empty(n, np.float32), np.empty(n, np.int32), np.empty(n, np.float32), np.empty(n, np.float32))
    counters = np.zeros((max(1, -(-n // KD_RAY_CHUNK)), N_COUNTERS), np.int64)
    on_threads(trace_kd_rays, numba.get_num_threads(), tree, tri_verts, origins, dirs, t_min, t_max, any_hit,
               KD_RAY_CHUNK, new_queue(), *out, counters)
    return (*out, counters.sum(axis=0))


def kd_light_visibility(tree: KdTree, tri_verts, rays, vis):
    """light_visibility's kd-tree twin: the same shadow rays (geometry/light_rays.
    LightRays), one any-hit single ray each, in the light-space order."""
    vis[:] = 0.0
    idx = rays.order[:rays.n_active]
    t, prim, _, _, counters = kd_trace_rays(tree, tri_verts, rays.origin[:, idx].T,
                                            rays.direction[:, idx].T, rays.t_min[idx],
                                            rays.t_max[idx], any_hit=True)
    vis[idx] = (prim < 0).astype(np.float32)
    return vis, counters
