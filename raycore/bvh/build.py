"""The BVH's binned-SAH build and its SAH cost (the node layout: bvh/nodes.py).

A build writes into a region of the arrays given to it (first node, first
reference), with absolute child indices, so that many trees (one per moving
object, one for all static objects) live in one set of arrays and a small
top-level tree over their roots joins them (bvh/scene.py). Unused nodes of
a region are marked child = -1, count = 0 and skipped.

Binned SAH (Wald 2007, "On fast construction of SAH-based bounding volume
hierarchies"): centroids binned into N_BINS per axis, all three axes in one
pass over the node's primitives, the cheapest of 3 (N_BINS - 1) planes taken.
Keyframed meshes keep their topology, so a tree built once is refit every
frame (bvh/refit.py) and rebuilt only when its SAH cost has grown past a
threshold measured against the cost at its last build.
"""
import heapq
import threading

import numpy as np

from numba.cpython.unsafe.numbers import trailing_zeros

from raycore.bvh.nodes import C_INTERSECT, C_TRAVERSE, CHILD, COUNT, SAH_DEPTH, STACK, half_area
from raycore.bvh.refit import REFIT_MIN_NODES, descendants_end
from raycore.jit.presets import helper, kernel
from raycore.jit.row8 import min_centroid_rows, min_rows, swap_rows
from raycore.jit.thread_pool import on_threads, thread_pool
from raycore.jit.tile_queue import next_tile
from raycore.jit.floats import INF

N_BINS = 16


@helper
def _tri_extent(tri_verts, t, a):
    """(lo, hi) of triangle t's finite corners along axis a (inf, -inf: none)."""
    lo = np.float32(np.inf)
    hi = np.float32(-np.inf)
    for c in range(3):
        x = tri_verts[t, 3 * c + a]
        lo = min(lo, x) if abs(x) < INF else lo
        hi = max(hi, x) if abs(x) < INF else hi
    return lo, hi


@kernel
def prim_bounds(tri_verts, tris, bounds, centroids):
    """Box (6) and centroid (3) of each triangle tris[k] of tri_verts (the
    reference the build's rows and centroids are tested against). A
    corner that is not finite is left out of the box (the grid does the
    same); a triangle with no finite corner gets an empty box. On one
    thread: the OpenMP threads of a parallel loop spin for a while after
    it, and took a core from the build's threads that follow (1-2 ms on hand)."""
    for k in range(tris.shape[0]):
        t = tris[k]
        for a in range(3):
            lo, hi = _tri_extent(tri_verts, t, a)
            bounds[k, a] = lo
            bounds[k, 3 + a] = hi
            centroids[k, a] = np.float32(0.5) * (lo + hi) if lo <= hi else np.float32(0.0)


# The build's data, 8 floats a row, so that a primitive's box is one vector
# (jit/row8.py): a primitive (m, 8) is lo x, y, z, its number (int32 bits),
# -hi x, y, z, 0; a bin's box (8) alike, and a span (16) a box, then its
# centroids' bounds as a row c x, y, z, 0, -c x, y, z, 0. Every bound is then a
# minimum (of -hi where it is a maximum), taken 8 lanes at a time: the same
# trees as with separate minima and maxima (-max(x) = min(-x) exactly),
# built 1.4-1.6x faster on two threads. A primitive's centroid is computed
# from its box where it is needed (_centroid, row8.min_centroid_rows): a row
# of its own held 32 bytes a triangle at the build's peak and doubled the
# rows each partition moves.
ROW = 8


@helper
def _grow(bins, r, x0, y0, z0, x1, y1, z1):
    """The box (x0..z1; x1..z1 as -hi) grown by bin row r."""
    return (min(x0, bins[r, 0]), min(y0, bins[r, 1]), min(z0, bins[r, 2]),
            min(x1, bins[r, 4]), min(y1, bins[r, 5]), min(z1, bins[r, 6]))


# the largest bin scale: N_BINS / extent overflows float32 for extents
# near the smallest float32 (triangles at 2^-125)
MAX_BIN_SCALE = np.float32(1e30)


@helper
def _bin_scale(ext):
    """Bins per unit of an axis whose centroids span `ext`: 0 (the axis is
    not binned) unless 0 < ext < inf, and never more than MAX_BIN_SCALE.
    Then (c - lo) * scale is finite and in [0, N_BINS) for every centroid c
    (0 <= c - lo <= ext), and int() of it is a bin. An infinite scale gave
    (c - lo) * scale = NaN at c = lo, and int(NaN) a negative bin: a write
    outside the bin arrays (found under NUMBA_BOUNDSCHECK)."""
    if not (ext > np.float32(0.0) and ext < INF):
        return np.float32(0.0)
    return min(np.float32(N_BINS) * np.float32(0.99999) / ext, MAX_BIN_SCALE)


@helper
def _centroid(prims, k, a):
    """Primitive k's centroid on axis a: (lo + hi) / 2, or 0 for a box with
    no finite corner on a (lo > hi), as prim_bounds gives it (lo - (-hi)
    is lo + hi exactly)."""
    lo = prims[k, a]
    neg_hi = prims[k, 4 + a]
    return np.float32(0.5) * (lo - neg_hi) if lo <= -neg_hi else np.float32(0.0)


@helper
def _empty(rows, i, n):
    """rows[i, :n] = inf: the start of a minimum."""
    for q in range(n):
        rows[i, q] = INF


@helper
def _span(prims, s, e, out, row):
    """out[row] (16) = the box and the centroids' bounds of primitives s..e-1
    (the root's, and the children of a split by count)."""
    box = out[row:row + 1, 0:ROW]
    cen = out[row:row + 1, ROW:2 * ROW]
    _empty(out, row, 2 * ROW)
    for k in range(s, e):
        min_rows(box, 0, prims, k)
        min_centroid_rows(cen, 0, prims, k)


# count of a node whose subtree is left to a job of its own
# (_split_on_threads); its child is the job's number among those its split made
DEFERRED = -4


@kernel
def _build_nodes(prims, max_leaf, s0, e0, depth0, span0, root, alloc0, box, child, count, stop_n,
                 task_s, task_e, task_d, task_span):
    """Binned-SAH subtree over primitives s0..e0-1 (their box and centroid
    bounds span0 (16,), at depth depth0) into the scratch node root and,
    for its descendants, the nodes alloc0, alloc0 + 1, ... (children in pairs).
    A node of fewer than stop_n primitives is not split here:
    it is marked DEFERRED and listed in task_* (first, end, depth, span),
    for build_region's workers. Returns (one past the last node used, tasks).
    prims (m, 8): see ROW; the partition moves its rows in place."""
    st_node = np.empty(STACK, np.int64)
    st_s = np.empty(STACK, np.int64)
    st_e = np.empty(STACK, np.int64)
    st_d = np.empty(STACK, np.int64)
    # each row's box and centroid bounds, gathered by the parent's partition
    # as it moves the primitives (a pass of its own per node cost 4-8 %)
    st_span = np.empty((STACK, 2 * ROW), np.float32)
    st_node[0], st_s[0], st_e[0], st_d[0] = root, s0, e0, depth0
    for q in range(2 * ROW):
        st_span[0, q] = span0[q]
    top = 1
    alloc = alloc0
    n_tasks = 0
    # bins start empty and are left empty: a node clears only those it
    # filled (bit b of filled[a]: bin b of axis a), and its sweeps visit only
    # those (scanning all 16 bins of each axis, twice, was a quarter of the build)
    bin_n = np.zeros((3, N_BINS), np.int64)
    bins = np.empty((3 * N_BINS, ROW), np.float32)
    for r in range(3 * N_BINS):
        _empty(bins, r, ROW)
    nonempty = np.empty(N_BINS, np.int64)     # an axis's bins that hold primitives
    filled = np.zeros(3, np.int64)
    r_area = np.empty(N_BINS, np.float32)
    r_n = np.empty(N_BINS, np.int64)
    spans = np.empty((4, ROW), np.float32)    # the two children's (box, centroids), while partitioning
    scale = np.empty(3, np.float32)           # bins per unit of each axis, this node's
    while top > 0:
        top -= 1
        node, s, e, depth = st_node[top], st_s[top], st_e[top], st_d[top]
        n = e - s
        lo0, lo1, lo2 = st_span[top, 0], st_span[top, 1], st_span[top, 2]
        hi0, hi1, hi2 = -st_span[top, 4], -st_span[top, 5], -st_span[top, 6]
        c_lo0, c_lo1, c_lo2 = st_span[top, 8], st_span[top, 9], st_span[top, 10]
        c_hi0, c_hi1, c_hi2 = -st_span[top, 12], -st_span[top, 13], -st_span[top, 14]
        box[node, 0], box[node, 1], box[node, 2] = lo0, lo1, lo2
        box[node, 3], box[node, 4], box[node, 5] = hi0, hi1, hi2
        if n < stop_n:
            child[node] = n_tasks
            count[node] = DEFERRED
            task_s[n_tasks], task_e[n_tasks], task_d[n_tasks] = s, e, depth
            for q in range(2 * ROW):
                task_span[n_tasks, q] = st_span[top, q]
            n_tasks += 1
            continue
        c_lo = (c_lo0, c_lo1, c_lo2)
        ext = (c_hi0 - c_lo0, c_hi1 - c_lo1, c_hi2 - c_lo2)
        best_cost = np.float32(np.inf)
        best_axis = -1
        best_bin = 0
        if n > 1 and depth < SAH_DEPTH and (ext[0] > 0 or ext[1] > 0 or ext[2] > 0):
            for a in range(3):
                scale[a] = _bin_scale(ext[a])
            for k in range(s, e):
                for a in range(3):
                    if scale[a] == 0:                  # not binned: c - lo may not be finite
                        continue
                    b = min(int((_centroid(prims, k, a) - c_lo[a]) * scale[a]), N_BINS - 1)
                    bin_n[a, b] += 1
                    filled[a] |= np.int64(1) << b
                    min_rows(bins, a * N_BINS + b, prims, k)
            for a in range(3):
                if scale[a] == 0:
                    continue
                # the sweeps run over the bins that hold primitives only (a
                # small node fills few of the 16): the plane after bin
                # nonempty[j] is the first of the planes up to the next full
                # bin, which all cost the same, so the tree is the one a
                # sweep over every bin makes (with a third of the build's time)
                k_full = 0
                bits = filled[a]
                while bits != 0:
                    b = trailing_zeros(bits)
                    bits &= bits - 1
                    nonempty[k_full] = b
                    k_full += 1
                # right-to-left sweep: area and count of the full bins j..
                x0 = y0 = z0 = x1 = y1 = z1 = INF
                cnt = 0
                for j in range(k_full - 1, 0, -1):
                    b = nonempty[j]
                    cnt += bin_n[a, b]
                    x0, y0, z0, x1, y1, z1 = _grow(bins, a * N_BINS + b, x0, y0, z0, x1, y1, z1)
                    r_n[j] = cnt
                    r_area[j] = half_area(x0, y0, z0, -x1, -y1, -z1)
                x0 = y0 = z0 = x1 = y1 = z1 = INF
                cnt = 0
                for j in range(k_full - 1):
                    b = nonempty[j]
                    cnt += bin_n[a, b]
                    x0, y0, z0, x1, y1, z1 = _grow(bins, a * N_BINS + b, x0, y0, z0, x1, y1, z1)
                    cost = (half_area(x0, y0, z0, -x1, -y1, -z1) * np.float32(cnt)
                            + r_area[j + 1] * np.float32(r_n[j + 1]))
                    if cost < best_cost:
                        best_cost, best_axis, best_bin = cost, a, b
            for a in range(3):
                bits = filled[a]
                while bits != 0:
                    b = trailing_zeros(bits)
                    bits &= bits - 1
                    bin_n[a, b] = 0
                    _empty(bins, a * N_BINS + b, ROW)
                filled[a] = 0
        area = half_area(lo0, lo1, lo2, hi0, hi1, hi2)
        split_cost = C_TRAVERSE + C_INTERSECT * best_cost / area if area > 0 else np.float32(np.inf)
        leaf_cost = C_INTERSECT * np.float32(n)
        if best_axis < 0 and n > max_leaf:
            # centroids all in one point, no finite area, or past SAH_DEPTH: split by count
            best_axis = -2
        if n <= max_leaf and (best_axis < 0 or leaf_cost <= split_cost):
            child[node] = s
            count[node] = n
            continue
        # the children's spans go to the two stack rows they will be popped from
        left, right = top + 1, top
        if best_axis >= 0:
            a = best_axis
            _empty(spans, 0, ROW)
            _empty(spans, 1, ROW)
            _empty(spans, 2, ROW)
            _empty(spans, 3, ROW)
            i, j = s, e - 1
            while i <= j:
                b = min(int((_centroid(prims, i, a) - c_lo[a]) * scale[a]), N_BINS - 1)
                if b <= best_bin:
                    min_rows(spans, 0, prims, i)
                    min_centroid_rows(spans, 1, prims, i)
                    i += 1
                else:
                    swap_rows(prims, i, j)
                    min_rows(spans, 2, prims, j)
                    min_centroid_rows(spans, 3, prims, j)
                    j -= 1
            mid = i
            split_axis = a
            if not (mid == s or mid == e):
                for q in range(ROW):
                    st_span[left, q] = spans[0, q]
                    st_span[left, ROW + q] = spans[1, q]
                    st_span[right, q] = spans[2, q]
                    st_span[right, ROW + q] = spans[3, q]
        else:
            mid = s + n // 2
            split_axis = 0
        if mid == s or mid == e or best_axis < 0:
            mid = s + n // 2
            _span(prims, s, mid, st_span, left)
            _span(prims, mid, e, st_span, right)
        child[node] = alloc
        count[node] = -1 - split_axis
        st_node[top], st_s[top], st_e[top], st_d[top] = alloc + 1, mid, e, depth + 1
        st_node[top + 1], st_s[top + 1], st_e[top + 1], st_d[top + 1] = alloc, s, mid, depth + 1
        top += 2
        alloc += 2
    return alloc, n_tasks


@kernel
def _relayout(s_box, s_child, s_count, node0, ref0, box, child, count):
    """The scratch tree (root 0, children in pairs wherever the build put
    them) copied into box, child, count from node0 (leaves' references
    from ref0) in depth-first order, children in pairs, left subtree first: the layout a single pass of
    _build_nodes makes, which refit_plan relies on. Returns the nodes used
    and the tree's SAH cost (as sah_cost, summed on the way)."""
    st_src = np.empty(STACK, np.int64)
    st_dst = np.empty(STACK, np.int64)
    st_src[0], st_dst[0] = 0, node0
    top = 1
    alloc = node0 + 1
    total = root_area = np.float64(0.0)
    while top > 0:
        top -= 1
        src, dst = st_src[top], st_dst[top]
        for q in range(6):
            box[dst, q] = s_box[src, q]
        c = s_count[src]
        count[dst] = c
        area = np.float64(half_area(s_box[src, 0], s_box[src, 1], s_box[src, 2], s_box[src, 3], s_box[src, 4],
                                s_box[src, 5]))
        if dst == node0:
            root_area = area
        if c > 0:
            total += area * np.float64(C_INTERSECT) * c
            child[dst] = s_child[src] + ref0
            continue
        total += area * np.float64(C_TRAVERSE)
        child[dst] = alloc
        st_src[top], st_dst[top] = s_child[src] + 1, alloc + 1
        st_src[top + 1], st_dst[top + 1] = s_child[src], alloc
        top += 2
        alloc += 2
    return alloc - node0, np.float32(total / root_area) if root_area > 0 else np.float32(0.0)


# build_region splits a tree's nodes of at least ~m / TASKS_PER_TREE
# primitives one split at a time, each split a job for the next free
# thread, the largest first (its two halves become jobs), and builds each
# node below that whole, as one job: from the second level on every thread
# has work (a first phase of splits on one thread down to m / 16 took a
# fifth of a 10M-triangle build). The workers are Python threads
# (jit/thread_pool.py), each calling the nogil kernel _build_nodes: as a
# numba parallel kernel (prange over the queue) the build compiled in 11 s
# instead of 4, its big loop optimized again inside the parallel region.
# 32 jobs a tree built as fast and held 85 MB more at 10M triangles (each
# job's scratch region ends in a huge page of its own)
TASKS_PER_TREE = 16
# jobs below this many primitives are not split further (a job costs ~20-30 us
# of Python and dispatch: 256 made 100K-triangle builds 5 % slower)
MIN_TASK = 2048
# the build's rows are made on all threads from this many primitives on
PARALLEL_ROWS = 1 << 16


@kernel
def _start_build(bounds, prims, span0):
    """prims (m, 8) (see ROW) from each primitive's box; span0[0] (16): the
    box and centroid bounds of them all (numpy's axis-0 min and max took
    9 ms on 77K triangles, a fifth of the build)."""
    prims_i = prims.view(np.int32)
    for i in range(bounds.shape[0]):
        for q in range(3):
            prims[i, q] = bounds[i, q]
            prims[i, 4 + q] = -bounds[i, 3 + q]
        prims_i[i, 3] = i
        prims[i, 7] = np.float32(0.0)
    _span(prims, 0, bounds.shape[0], span0, 0)


@kernel
def _start_build_tris(tri_verts, tris, prims, spans, j, k0, k1):
    """_start_build's rows k0..k1-1 straight from triangles tris[k0:k1] of
    tri_verts, with prim_bounds's boxes, bit for bit, and without their
    (m, 6) array (a first build at 10M triangles held 360 MB of boxes and
    centroids); spans[j]: those rows' span (part j of _rows_of_tris)."""
    prims_i = prims.view(np.int32)
    for k in range(k0, k1):
        t = tris[k]
        for a in range(3):
            lo, hi = _tri_extent(tri_verts, t, a)
            prims[k, a] = lo
            prims[k, 4 + a] = -hi
        prims_i[k, 3] = k
        prims[k, 7] = np.float32(0.0)
    _span(prims, k0, k1, spans, j)


def on_parts(kernel, n, n_parts, *args):
    """kernel(*args, j, k0, k1) for each part j (k0..k1-1) of n_parts
    consecutive parts of 0..n-1, at once on as many threads
    (thread_pool.on_threads; one part: on this thread)."""
    cuts = np.linspace(0, n, max(n_parts, 1) + 1).astype(np.int64).tolist()
    parts = [(j, cuts[j], cuts[j + 1]) for j in range(len(cuts) - 1)]
    on_threads(lambda *a: kernel(*a[:-1], *a[-1]), len(parts), *args, per_worker=parts)


def _rows_of_tris(tri_verts, tris, n_workers):
    """The build's rows (prims, span0) of triangles tris, made on
    n_workers threads from PARALLEL_ROWS triangles on (the span of each
    part, then their minimum: every lane of a span is one)."""
    m = tris.shape[0]
    prims, _ = _empty_rows(m)
    n_parts = max(n_workers, 1) if m >= PARALLEL_ROWS else 1
    spans = np.empty((n_parts, 2 * ROW), np.float32)
    on_parts(_start_build_tris, m, n_parts, tri_verts, tris, prims, spans)
    return prims, spans.min(axis=0, keepdims=True)


def build_region_of_tris(tri_verts, tris, max_leaf, node0, ref0, box, child, count, order, n_workers=1):
    """build_region over the triangles tris of tri_verts (their boxes and
    centroids as prim_bounds gives them), the same tree."""
    return _build_rows(list(_rows_of_tris(tri_verts, tris, n_workers)), max_leaf, node0, ref0, box, child, count,
                       order, n_workers)


def build_region(bounds, max_leaf, node0, ref0, box, child, count, order, n_workers=1):
    """Binned-SAH tree over primitives 0..m-1 (bounds (m, 6); their
    centroids (lo + hi) / 2, 0 on an axis where lo > hi) into the
    node region starting at node0 (root there, children in pairs after it).
    `order` (m,) receives the primitives in leaf order: leaf k's references
    are order[child[k] - ref0 ...] (child counts from the caller's
    reference base ref0). Returns the nodes used and the tree's SAH cost
    (sah_cost's, summed while laying it out). bounds is read only (copied
    into the build's rows, see ROW).

    Nodes of ~m / TASKS_PER_TREE primitives and more are split one at a
    time by n_workers threads, the subtrees below them built whole, each
    into a scratch region of its own; then one pass lays the nodes out as a
    single serial pass would, so the tree does not depend on the thread
    count (nor on whether it was built in parallel at all)."""
    prims, span0 = _empty_rows(bounds.shape[0])
    _start_build(bounds, prims, span0)
    rows = [prims, span0]
    del prims
    return _build_rows(rows, max_leaf, node0, ref0, box, child, count, order, n_workers)


def _empty_rows(m):
    """The build's rows of m primitives and their span (see ROW)."""
    return np.empty((m, ROW), np.float32), np.empty((1, 2 * ROW), np.float32)


def _build_rows(rows, max_leaf, node0, ref0, box, child, count, order, n_workers):
    """build_region from its primitives' rows: the list [prims, span0],
    emptied here, so that the rows (32 bytes a primitive) are freed once
    the leaf order is read, before the nodes are laid out (at 10M
    triangles the build's peak was rows, scratch and nodes at once)."""
    prims, span0 = rows
    rows.clear()
    m = prims.shape[0]
    # scratch nodes: the root (0) and the split jobs' children, pairs from 1
    # on (at most one split per primitive), then each subtree built whole
    # from 2m + 2 + 2 x its first primitive (its descendants: < 2 x its
    # primitives); child and count as int32, which at 10M triangles held
    # 90 MB less at the peak than int64
    n_scratch = 4 * m + 2
    s_box = np.empty((n_scratch, 6), np.float32)
    s_child = np.empty(n_scratch, np.int32)
    s_count = np.empty(n_scratch, np.int32)
    no_task = np.empty(1, np.int64)
    if n_workers > 1 and m >= 2 * MIN_TASK:
        _split_on_threads(prims, span0[0], max_leaf, s_box, s_child, s_count, n_workers,
                          max(m // TASKS_PER_TREE, MIN_TASK))
    else:
        _build_nodes(prims, max_leaf, 0, m, 1, span0[0], 0, 1, s_box, s_child, s_count, 0,
                     no_task, no_task, no_task, np.empty((1, 2 * ROW), np.float32))
    order[:] = prims.view(np.int32)[:, 3]
    del prims
    return _relayout(s_box, s_child, s_count, node0, ref0, box, child, count)


def _split_on_threads(prims, span0, max_leaf, s_box, s_child, s_count, n_workers, stop_n):
    """The tree over all m rows into the scratch nodes (root 0) by n_workers
    threads, sharing one list of jobs, the largest first: a job of at least
    stop_n primitives is one split (its node and its children's pair; the
    children become jobs), a smaller one its whole subtree."""
    m = prims.shape[0]
    base = 2 * m + 2
    jobs = [(-m, 0, m, 1, span0.copy(), 0)]       # (-size, first, end, depth, span, node)
    state = {"pairs": 1, "busy": 0}
    ready = threading.Condition()

    def work():
        two_s, two_e, two_d = (np.empty(2, np.int64) for _ in range(3))
        two_span = np.empty((2, 2 * ROW), np.float32)
        while True:
            with ready:
                while not jobs and state["busy"]:
                    ready.wait()
                if not jobs:
                    return
                _, s, e, depth, span, node = heapq.heappop(jobs)
                state["busy"] += 1
                split = e - s >= stop_n
                if split:
                    pair = state["pairs"]
                    state["pairs"] += 2
            new = []
            try:
                if split:
                    # stop_n = the job's size: the node is split, its children deferred as two jobs
                    _, n_new = _build_nodes(prims, max_leaf, s, e, depth, span, node, pair, s_box,
                                            s_child, s_count, e - s, two_s, two_e, two_d, two_span)
                    for t in range(n_new):
                        at = pair if s_child[pair] == t else pair + 1
                        new.append((-int(two_e[t] - two_s[t]), int(two_s[t]), int(two_e[t]), int(two_d[t]),
                                    two_span[t].copy(), at))
                else:
                    _build_nodes(prims, max_leaf, s, e, depth, span, node, base + 2 * s, s_box, s_child,
                                 s_count, 0, two_s, two_e, two_d, two_span)
            finally:
                with ready:
                    for job in new:
                        heapq.heappush(jobs, job)
                    state["busy"] -= 1
                    ready.notify_all()

    pool = thread_pool("bvh-build", n_workers - 1)
    helpers = [pool.submit(work) for _ in range(n_workers - 1)]
    try:
        work()
    finally:
        for h in helpers:
            h.result()


@kernel
def gather_references(tris, order, tri_verts, faces, r0, tri, verts, leaf_faces, j, k0, k1):
    """References r0, r0 + 1, ... in leaf order (build_region's `order` of
    the triangles `tris`): each one's global id, corners and vertex ids,
    in one pass (numpy's three gathers took 15 % of a build): those of
    order[k0:k1] (part j of on_parts; the whole order: 0, 0, len(order)).
    Not a parallel kernel, as prim_bounds: a spinning OpenMP thread would
    slow the next tree's build."""
    for k in range(k0, k1):
        t = tris[order[k]]
        tri[r0 + k] = t
        for q in range(9):
            verts[r0 + k, q] = tri_verts[t, q]
        for q in range(3):
            leaf_faces[r0 + k, q] = faces[t, q]


@kernel
def sah_cost(box, child, count, root):
    """SAH cost of the tree under `root`, relative to the root's area: the
    expected number of node visits and triangle tests of a random ray that
    hits the root box (traversal and test weighted by the build's constants)."""
    root_area = half_area(box[root, 0], box[root, 1], box[root, 2], box[root, 3], box[root, 4], box[root, 5])
    if not root_area > 0:
        return np.float32(0.0)
    stack = np.empty(STACK, np.int64)
    stack[0] = root
    top = 1
    total = np.float64(0.0)
    while top > 0:
        top -= 1
        i = stack[top]
        a = np.float64(half_area(box[i, 0], box[i, 1], box[i, 2], box[i, 3], box[i, 4], box[i, 5]))
        if count[i] > 0:
            total += a * np.float64(C_INTERSECT) * count[i]
        else:
            total += a * np.float64(C_TRAVERSE)
            stack[top] = child[i]
            stack[top + 1] = child[i] + 1
            top += 2
    return np.float32(total / root_area)


# build_small_trees takes trees below this many triangles: build_region
# splits them on one thread all the same (below 2 MIN_TASK), and their
# fewer than REFIT_MIN_NODES nodes are refit in one piece
SMALL_TREE = REFIT_MIN_NODES // 2


@kernel
def build_small_trees(tri_verts, faces, tris, tri_start, which, node_lo, ref_lo, max_leaf, node, node_i, tri,
                      verts, leaf_faces, used, cost, run_end, queue):
    """Trees `which` (each of fewer than SMALL_TREE triangles: tree g's are
    tris[tri_start[g]:tri_start[g + 1]]) built into their regions as
    bvh/scene.py's one-tree path builds them (build_region_of_tris,
    unused nodes cleared, gather_references), in one call: that path spends
    ~25 us of Python and dispatch a tree around ~15-20 us of building, and
    tumbling marbles rebuild ~9 trees of 80 triangles a frame (up to 50). Into
    used[j], cost[j], run_end[j] (refit_plan's one piece) for which[j].
    The trees this thread pulls from `queue` (thread_pool.on_threads
    starts one a thread; the trees' regions are disjoint)."""
    box = node[:, :6]
    child = node_i[:, CHILD]
    count = node_i[:, COUNT]
    no_tasks = np.empty(1, np.int64)
    no_span = np.empty((1, 2 * ROW), np.float32)
    while True:
        j = next_tile(queue, which.shape[0])
        if j < 0:
            break
        g = which[j]
        group = tris[tri_start[g]:tri_start[g + 1]]
        m = group.shape[0]
        n0, r0 = node_lo[g], ref_lo[g]
        prims = np.empty((m, ROW), np.float32)
        span0 = np.empty((1, 2 * ROW), np.float32)
        _start_build_tris(tri_verts, group, prims, span0, 0, 0, m)
        s_box = np.empty((4 * m + 1, 6), np.float32)
        s_child = np.empty(4 * m + 1, np.int32)
        s_count = np.empty(4 * m + 1, np.int32)
        _build_nodes(prims, max_leaf, 0, m, 1, span0[0], 0, 1, s_box, s_child, s_count, 0,
                     no_tasks, no_tasks, no_tasks, no_span)
        order = prims.view(np.int32)[:, 3].copy()
        n_used, c = _relayout(s_box, s_child, s_count, n0, r0, box, child, count)
        for i in range(n0 + n_used, n0 + 2 * m):
            child[i] = -1
            count[i] = 0
        gather_references(group, order, tri_verts, faces, r0, tri, verts, leaf_faces, 0, 0, m)
        used[j] = n_used
        cost[j] = c
        run_end[j] = descendants_end(child, count, n0) if count[n0] <= 0 and child[n0] >= 0 else n0 + 1


