"""Bounding volume hierarchy: binned-SAH build, refit, and its SAH cost.

Flat arrays, no pointers (as the kd-tree): node i is a leaf when count[i] > 0,
listing count[i] references from child[i]; else its two children are
child[i] and child[i] + 1 (allocated as a pair), and count[i] = -1 - axis
names the axis it was split on (traversal visits the child nearer along it
first). A node is one 32-byte row: its box (6 floats), child and count
(two int32 in the same row, through an int32 view of the same memory), so
that a visit reads one cache line, and two siblings share one: separate
arrays for box, child, count and axis cost four. A reference
is a triangle: `tri` holds its global id and `verts` its corners in leaf
order, refreshed by every refit, so that a leaf's triangles are read from one
contiguous run of memory instead of being gathered from the whole scene.

A build writes into a region of the arrays given to it (first node, first
reference), with absolute child indices, so that many trees (one per moving
object, one for all static objects) live in one set of arrays and a small
top-level tree over their roots joins them (scene_bvh.py). Unused nodes of
a region are marked child = -1, count = 0 and skipped.

Binned SAH (Wald 2007, "On fast construction of SAH-based bounding volume
hierarchies"): centroids binned into N_BINS per axis, all three axes in one
pass over the node's primitives, the cheapest of 3 (N_BINS - 1) planes taken.
Keyframed meshes keep their topology, so a tree built once is refit every
frame (boxes recomputed bottom-up, nodes in reverse order since children
always follow their parent) and rebuilt only when its SAH cost has grown
past a threshold measured against the cost at its last build.
"""
from typing import NamedTuple

import numpy as np

from numba import prange
from numba.cpython.unsafe.numbers import trailing_zeros

from ._jit import helper, kernel, parallel_kernel
from .row8 import min_rows, swap_rows
from .thread_pool import thread_pool
from .tile_queue import next_tile

N_BINS = 16
# SAH constants: a node visit of a packet (its frustum test, a box test of
# one or more 16-ray chunks, the stack) costs about three ray/triangle tests
# of a chunk (~200 cycles against ~40-70 on this machine kind's shadow
# packets). With C_TRAVERSE 3 instead of 1 the trees have larger leaves and
# a shadow packet visits 15-30 % fewer nodes; on rays captured from the
# built-in scenes, one thread, three rounds alternating, shadow ms hand
# 26.9-28.3 -> 25.8-27.8, runner 32.1-33.0 -> 28.2-30.1, marbles 30.0-30.4
# -> 28.1-28.3, the others within the noise (2 and 4: between 1 and 3; a
# leaf cap of 12 or 16: no larger leaves); camera packets the same.
# Leaves up to MAX_LEAF triangles.
MAX_LEAF = 8
C_TRAVERSE = np.float32(3.0)
C_INTERSECT = np.float32(1.0)
INF = np.float32(np.inf)
# Depth. Binned SAH on coordinates spread over the float range peels off a
# few triangles per level (triangles at 2^-125 .. 2^125: depth 58 for 8K
# of them, 107 for 256K), and the stacks below have no bounds checks. So
# from SAH_DEPTH down a node is split by count (halves): a tree is never deeper
# than MAX_DEPTH (32 halvings hold 2^32 triangles), and a walk through the
# top level and one tree never holds more than STACK entries.
SAH_DEPTH = 48
MAX_DEPTH = SAH_DEPTH + 32
STACK = 2 * MAX_DEPTH + 2


CHILD, COUNT = 6, 7          # int32 columns of a node row


class Bvh(NamedTuple):
    node: np.ndarray      # (n_nodes, 8) f32: lo x, y, z, hi x, y, z, then two int32 (node_i)
    node_i: np.ndarray    # the same memory as int32: [:, CHILD] first child (inner) or first
                          # reference (leaf), -1 unused; [:, COUNT] references (leaf), -1 - axis (inner)
    tri: np.ndarray       # (n_refs,) i32: global triangle id of each reference
    verts: np.ndarray     # (n_refs, 9) f32: its corners, in leaf order

    @property
    def box(self):
        return self.node[:, :6]

    @property
    def child(self):
        return self.node_i[:, CHILD]

    @property
    def count(self):
        """References of a leaf; 0 or less for inner and unused nodes."""
        return self.node_i[:, COUNT]


def empty_bvh(n_nodes, n_refs) -> Bvh:
    node = np.zeros((n_nodes, 8), np.float32)
    node_i = node.view(np.int32)
    node_i[:, CHILD] = -1
    return Bvh(node, node_i, np.zeros(n_refs, np.int32), np.zeros((n_refs, 9), np.float32))


@kernel
def prim_bounds(tri_verts, tris, bounds, centroids):
    """Box (6) and centroid (3) of each triangle tris[k] of tri_verts. A
    corner that is not finite is left out of the box (the grid does the
    same); a triangle with no finite corner gets an empty box. On one
    thread: the OpenMP threads of a parallel loop spin for a while after
    it, and took a core from the build's threads that follow (1-2 ms on hand)."""
    for k in range(tris.shape[0]):
        t = tris[k]
        for a in range(3):
            lo = np.float32(np.inf)
            hi = np.float32(-np.inf)
            for c in range(3):
                x = tri_verts[t, 3 * c + a]
                lo = min(lo, x) if abs(x) < INF else lo
                hi = max(hi, x) if abs(x) < INF else hi
            bounds[k, a] = lo
            bounds[k, 3 + a] = hi
            centroids[k, a] = np.float32(0.5) * (lo + hi) if lo <= hi else np.float32(0.0)


@kernel
def _area(x0, y0, z0, x1, y1, z1):
    dx = max(x1 - x0, np.float32(0.0))
    dy = max(y1 - y0, np.float32(0.0))
    dz = max(z1 - z0, np.float32(0.0))
    return dx * dy + dy * dz + dz * dx


# The build's data, 8 floats a row, so that a primitive's box is one vector
# (row8.py): a primitive (m, 8) is lo x, y, z, its number (int32 bits),
# -hi x, y, z, 0; its centroid (m, 8) c x, y, z, 0, -c x, y, z, 0; a bin's box
# (8) and a span (16: box, then centroid bounds) alike. Every bound is then a
# minimum (of -hi where it is a maximum), taken 8 lanes at a time: the same
# trees as with separate minima and maxima (-max(x) = min(-x) exactly),
# built 1.4-1.6x faster on two threads.
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
def _empty(rows, i, n):
    """rows[i, :n] = inf: the start of a minimum."""
    for q in range(n):
        rows[i, q] = INF


@helper
def _span(prims, cents, s, e, out, row):
    """out[row] (16) = the box and the centroids' bounds of primitives s..e-1
    (the root's, and the children of a split by count)."""
    box = out[row:row + 1, 0:ROW]
    cen = out[row:row + 1, ROW:2 * ROW]
    _empty(out, row, 2 * ROW)
    for k in range(s, e):
        min_rows(box, 0, prims, k)
        min_rows(cen, 0, cents, k)


# count of a node whose subtree is left to a task (build_region's top
# phase); its child is the task's number
DEFERRED = -4


@kernel
def _build_nodes(prims, cents, max_leaf, s0, e0, depth0, span0, root, box, child, count, stop_n,
                 task_s, task_e, task_d, task_span):
    """Binned-SAH subtree over primitives s0..e0-1 (their box and centroid
    bounds span0 (16,), at depth depth0) into the scratch nodes root, root + 1, ...
    (children in pairs after their parent, in the order build_region lays
    them out). A node of fewer than stop_n primitives is not split here:
    it is marked DEFERRED and listed in task_* (first, end, depth, span),
    for build_region's workers. Returns (one past the last node used, tasks).
    prims, cents (m, 8): see ROW; the partition moves their rows in place."""
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
    alloc = root + 1
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
                    b = min(int((cents[k, a] - c_lo[a]) * scale[a]), N_BINS - 1)
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
                    r_area[j] = _area(x0, y0, z0, -x1, -y1, -z1)
                x0 = y0 = z0 = x1 = y1 = z1 = INF
                cnt = 0
                for j in range(k_full - 1):
                    b = nonempty[j]
                    cnt += bin_n[a, b]
                    x0, y0, z0, x1, y1, z1 = _grow(bins, a * N_BINS + b, x0, y0, z0, x1, y1, z1)
                    cost = (_area(x0, y0, z0, -x1, -y1, -z1) * np.float32(cnt)
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
        area = _area(lo0, lo1, lo2, hi0, hi1, hi2)
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
                b = min(int((cents[i, a] - c_lo[a]) * scale[a]), N_BINS - 1)
                if b <= best_bin:
                    min_rows(spans, 0, prims, i)
                    min_rows(spans, 1, cents, i)
                    i += 1
                else:
                    swap_rows(prims, i, j)
                    swap_rows(cents, i, j)
                    min_rows(spans, 2, prims, j)
                    min_rows(spans, 3, cents, j)
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
            _span(prims, cents, s, mid, st_span, left)
            _span(prims, cents, mid, e, st_span, right)
        child[node] = alloc
        count[node] = -1 - split_axis
        st_node[top], st_s[top], st_e[top], st_d[top] = alloc + 1, mid, e, depth + 1
        st_node[top + 1], st_s[top + 1], st_e[top + 1], st_d[top + 1] = alloc, s, mid, depth + 1
        top += 2
        alloc += 2
    return alloc, n_tasks


@kernel
def _relayout(s_box, s_child, s_count, task_root, node0, ref0, box, child, count):
    """The scratch tree (root 0, DEFERRED nodes continued at their task's
    root) copied into box, child, count from node0 (leaves' references
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
        if s_count[src] == DEFERRED:
            src = task_root[s_child[src]]
        for q in range(6):
            box[dst, q] = s_box[src, q]
        c = s_count[src]
        count[dst] = c
        area = np.float64(_area(s_box[src, 0], s_box[src, 1], s_box[src, 2], s_box[src, 3], s_box[src, 4],
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


# build_region's top phase splits nodes down to about 1 / TASKS_PER_TREE
# of the primitives; the subtrees below are built by all threads, pulled
# from a queue (more tasks than threads, so the load balances). The workers
# are Python threads (thread_pool.py), each calling the nogil kernel
# _build_nodes: as a numba parallel kernel (prange over the queue) the
# build compiled in 11 s instead of 4, its big loop optimized again inside
# the parallel region
TASKS_PER_TREE = 16
MIN_TASK = 256


@kernel
def _start_build(bounds, centroids, prims, cents, span0):
    """prims, cents (m, 8) (see ROW) from each primitive's box and centroid;
    span0[0] (16): the box and centroid bounds of them all (numpy's axis-0
    min and max took 9 ms on 77K triangles, a fifth of the build)."""
    prims_i = prims.view(np.int32)
    for i in range(bounds.shape[0]):
        for q in range(3):
            prims[i, q] = bounds[i, q]
            prims[i, 4 + q] = -bounds[i, 3 + q]
            cents[i, q] = centroids[i, q]
            cents[i, 4 + q] = -centroids[i, q]
        prims_i[i, 3] = i
        prims[i, 7] = np.float32(0.0)
        cents[i, 3] = np.float32(0.0)
        cents[i, 7] = np.float32(0.0)
    _span(prims, cents, 0, bounds.shape[0], span0, 0)


def build_region(bounds, centroids, max_leaf, node0, ref0, box, child, count, order, n_workers=1):
    """Binned-SAH tree over primitives 0..m-1 (bounds, centroids) into the
    node region starting at node0 (root there, children in pairs after it).
    `order` (m,) receives the primitives in leaf order: leaf k's references
    are order[child[k] - ref0 ...] (child counts from the caller's
    reference base ref0). Returns the nodes used and the tree's SAH cost
    (sah_cost's, summed while laying it out). bounds and centroids are
    read only (copied into the build's rows, see ROW).

    The nodes above ~m / TASKS_PER_TREE primitives are split on one thread;
    the subtrees below them by n_workers threads into disjoint scratch
    regions; then one pass lays the nodes out as a single serial pass
    would, so the tree does not depend on the thread count (nor on whether
    it was built in parallel at all)."""
    m = bounds.shape[0]
    prims = np.empty((m, ROW), np.float32)
    cents = np.empty((m, ROW), np.float32)
    span0 = np.empty((1, 2 * ROW), np.float32)
    _start_build(bounds, centroids, prims, cents, span0)
    # a binary tree over m primitives has at most 2m - 1 nodes: the top
    # phase's first, then each task's from 2 x its first primitive on
    n_scratch = 4 * m + 1
    s_box = np.empty((n_scratch, 6), np.float32)
    s_child = np.empty(n_scratch, np.int64)
    s_count = np.empty(n_scratch, np.int64)
    stop_n = max(m // TASKS_PER_TREE, MIN_TASK) if n_workers > 1 and m >= 2 * MIN_TASK else 0
    n_max = m + 1 if stop_n else 1          # tasks hold disjoint runs of primitives
    task_s, task_e, task_d = (np.empty(n_max, np.int64) for _ in range(3))
    task_span = np.empty((n_max, 2 * ROW), np.float32)
    top_end, n_tasks = _build_nodes(prims, cents, max_leaf, 0, m, 1, span0[0], 0, s_box, s_child, s_count,
                                    stop_n, task_s, task_e, task_d, task_span)
    task_root = top_end + 2 * task_s[:n_tasks]
    if n_tasks:
        tasks = iter(range(n_tasks))            # next() on it is atomic under the GIL

        def work():
            for t in tasks:
                _build_nodes(prims, cents, max_leaf, task_s[t], task_e[t], task_d[t], task_span[t],
                             task_root[t], s_box, s_child, s_count, 0, task_s, task_e, task_d, task_span)

        pool = thread_pool("bvh-build", n_workers - 1)
        helpers = [pool.submit(work) for _ in range(min(n_workers, n_tasks) - 1)]
        work()
        for h in helpers:
            h.result()
    order[:] = prims.view(np.int32)[:, 3]
    return _relayout(s_box, s_child, s_count, task_root, node0, ref0, box, child, count)


@kernel
def gather_references(tris, order, tri_verts, faces, r0, tri, verts, leaf_faces):
    """References r0, r0 + 1, ... in leaf order (build_region's `order` of
    the triangles `tris`): each one's global id, corners and vertex ids,
    in one pass (numpy's three gathers took 15 % of a build; on one thread,
    as prim_bounds, so that no spinning thread slows the next tree's build)."""
    for k in range(order.shape[0]):
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
    root_area = _area(box[root, 0], box[root, 1], box[root, 2], box[root, 3], box[root, 4], box[root, 5])
    if not root_area > 0:
        return np.float32(0.0)
    stack = np.empty(STACK, np.int64)
    stack[0] = root
    top = 1
    total = np.float64(0.0)
    while top > 0:
        top -= 1
        i = stack[top]
        a = np.float64(_area(box[i, 0], box[i, 1], box[i, 2], box[i, 3], box[i, 4], box[i, 5]))
        if count[i] > 0:
            total += a * np.float64(C_INTERSECT) * count[i]
        else:
            total += a * np.float64(C_TRAVERSE)
            stack[top] = child[i]
            stack[top + 1] = child[i] + 1
            top += 2
    return np.float32(total / root_area)


# a refit's inner nodes are shared out as about this many subtrees per
# tree (fixed, so that the SAH sums and their order do not depend on the
# thread count); trees of fewer nodes are one piece
REFIT_PIECES = 16
REFIT_MIN_NODES = 512


def refit_plan(child, count, root, used):
    """What refit needs of one tree (nodes root..root+used-1), made once per
    build: `front`, subtrees that cover it, and `front_end`, the end of each
    one's descendants; `tops`, the nodes above them, last first.

    The build pushes a node's right child below its left one, so a node's
    descendants are the contiguous run child[x] .. front_end - 1 (the left
    subtree's, then the right one's): every piece is refit from the end of
    its run back to its root with no other piece's node in between."""
    # in Python (no compile for a few calls a build), each node looked at
    # once: looking at every piece again at every split took 0.4-1.6 ms of
    # a scene's build (a third of toys' and the demo's)
    seen = {}

    def node(x):
        """(inner, first child, run end) of node x."""
        if x not in seen:
            inner = bool(count[x] <= 0 and child[x] >= 0)
            seen[x] = (inner, int(child[x]), _run_end.py_func(child, count, x) if inner else x + 1)
        return seen[x]
    front, tops = [root], []
    if used >= REFIT_MIN_NODES:
        while len(front) < REFIT_PIECES:
            inner = [x for x in front if node(x)[0]]
            if not inner:
                break
            x = max(inner, key=lambda y: node(y)[2] - node(y)[1])   # the largest piece
            front.remove(x)
            tops.append(x)
            front += [node(x)[1], node(x)[1] + 1]
    front.sort()
    ends = [node(x)[2] for x in front]
    return np.array(front, np.int64), np.array(ends, np.int64), np.array(sorted(tops, reverse=True), np.int64)


@helper
def _run_end(child, count, x):
    """One past the last descendant of inner node x (see refit_plan)."""
    while True:
        c = int(child[x])
        if count[c + 1] <= 0 and child[c + 1] >= 0:
            x = c + 1
        elif count[c] <= 0 and child[c] >= 0:
            x = c
        else:
            return c + 2


# build_small_trees takes trees below this many triangles: build_region
# splits them on one thread all the same (below 2 MIN_TASK), and their
# fewer than REFIT_MIN_NODES nodes are refit in one piece
SMALL_TREE = min(2 * MIN_TASK, REFIT_MIN_NODES // 2)


@kernel
def build_small_trees(tri_verts, faces, tris, tri_start, which, node_lo, ref_lo, max_leaf, node, node_i, tri,
                      verts, leaf_faces, used, cost, run_end, queue):
    """Trees `which` (each of fewer than SMALL_TREE triangles: tree g's are
    tris[tri_start[g]:tri_start[g + 1]]) built into their regions as
    scene_bvh's one-tree path builds them (prim_bounds, build_region,
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
        bounds = np.empty((m, 6), np.float32)
        centroids = np.empty((m, 3), np.float32)
        prim_bounds(tri_verts, group, bounds, centroids)
        prims = np.empty((m, ROW), np.float32)
        cents = np.empty((m, ROW), np.float32)
        span0 = np.empty((1, 2 * ROW), np.float32)
        _start_build(bounds, centroids, prims, cents, span0)
        s_box = np.empty((4 * m + 1, 6), np.float32)
        s_child = np.empty(4 * m + 1, np.int64)
        s_count = np.empty(4 * m + 1, np.int64)
        _build_nodes(prims, cents, max_leaf, 0, m, 1, span0[0], 0, s_box, s_child, s_count, 0,
                     no_tasks, no_tasks, no_tasks, no_span)
        order = prims.view(np.int32)[:, 3].copy()
        n_used, c = _relayout(s_box, s_child, s_count, no_tasks, n0, r0, box, child, count)
        for i in range(n0 + n_used, n0 + 2 * m):
            child[i] = -1
            count[i] = 0
        gather_references(group, order, tri_verts, faces, r0, tri, verts, leaf_faces)
        used[j] = n_used
        cost[j] = c
        run_end[j] = _run_end(child, count, n0) if count[n0] <= 0 and child[n0] >= 0 else n0 + 1


@helper
def _union_children(node, node_i, i):
    """Inner node i's box from its two children's (they follow it in memory)."""
    left = node_i[i, CHILD]
    for q in range(3):
        node[i, q] = min(node[left, q], node[left + 1, q])
        node[i, 3 + q] = max(node[left, 3 + q], node[left + 1, 3 + q])


@helper
def _refit_leaf(vertices, node, leaf_faces, verts, i, first, c):
    """Leaf i's box from its triangles' corners now (their vertices'
    positions, through leaf_faces, each reference's three vertex ids),
    copied into `verts` in leaf order. Corners that are not finite are left out, as in the build:
    the first pass takes every corner and notes (x * 0 is NaN only for inf
    and NaN) whether one was not finite; only then is the leaf boxed again
    corner by corner. One test a leaf instead of six a corner: refit
    20-25 % faster on runner and hand."""
    x0 = y0 = z0 = np.float32(np.inf)
    x1 = y1 = z1 = np.float32(-np.inf)
    odd = np.float32(0.0)
    for r in range(first, first + c):
        for v in range(3):
            p = leaf_faces[r, v]
            x = vertices[p, 0]
            y = vertices[p, 1]
            z = vertices[p, 2]
            verts[r, 3 * v] = x
            verts[r, 3 * v + 1] = y
            verts[r, 3 * v + 2] = z
            odd += x * np.float32(0.0) + y * np.float32(0.0) + z * np.float32(0.0)
            x0, x1 = min(x0, x), max(x1, x)
            y0, y1 = min(y0, y), max(y1, y)
            z0, z1 = min(z0, z), max(z1, z)
    if odd != odd:                                    # a corner was inf or NaN
        x0 = y0 = z0 = np.float32(np.inf)
        x1 = y1 = z1 = np.float32(-np.inf)
        for r in range(first, first + c):
            for v in range(3):
                # abs(x) < inf: finite (np.isfinite on a scalar is a call)
                x = verts[r, 3 * v]
                y = verts[r, 3 * v + 1]
                z = verts[r, 3 * v + 2]
                x0, x1 = (min(x0, x), max(x1, x)) if abs(x) < INF else (x0, x1)
                y0, y1 = (min(y0, y), max(y1, y)) if abs(y) < INF else (y0, y1)
                z0, z1 = (min(z0, z), max(z1, z)) if abs(z) < INF else (z0, z1)
    node[i, 0], node[i, 1], node[i, 2] = x0, y0, z0
    node[i, 3], node[i, 4], node[i, 5] = x1, y1, z1


@helper
def _refit_node(vertices, node, node_i, leaf_faces, verts, i):
    """Node i's box: a leaf's from its triangles (_refit_leaf), an inner
    node's from its children's. Returns its SAH term (area times the
    node's cost)."""
    c = node_i[i, COUNT]
    if c > 0:
        _refit_leaf(vertices, node, leaf_faces, verts, i, node_i[i, CHILD], c)
    elif node_i[i, CHILD] < 0:
        return np.float64(0.0)
    else:
        _union_children(node, node_i, i)
    a = np.float64(_area(node[i, 0], node[i, 1], node[i, 2], node[i, 3], node[i, 4], node[i, 5]))
    return a * (np.float64(C_INTERSECT) * c if c > 0 else np.float64(C_TRAVERSE))


@parallel_kernel
def refit(vertices, front, front_end, front_start, tops, tops_start, roots, node, node_i, leaf_faces,
          verts, part, cost):
    """Refit trees to the triangles' positions now (tree g: root roots[g],
    pieces front[front_start[g]:front_start[g+1]], nodes above them
    tops[tops_start[g]:...]; refit_plan; -1 marks an unused slot). Every piece, in parallel, walks
    its run of nodes from the end back to its root (children always follow
    their parent, so a node's are done before it: a walk through memory,
    measured 3x faster than breadth first on 100K triangles), boxing leaves
    from their triangles and inner nodes from their children, and sums its
    SAH terms into part; then each tree's few top nodes, and cost[g], the
    SAH cost relative to the root's area (as sah_cost). One big tree (a
    runner) is no longer refit on one thread, and a piece's leaves and
    inner nodes are boxed while in cache, in one parallel loop. Corners are
    read from the shared vertices (leaf_faces: each reference's vertex ids,
    in leaf order), not from the per-triangle corners: a mesh's vertex
    array is a sixth of that size and stays in cache (runner's refit 41 %
    faster)."""
    for f in prange(front.shape[0]):
        x = front[f]
        if x < 0:                                      # an unused slot
            part[f] = 0.0
            continue
        # an inner node's run from its end back to child[x], then x itself
        # (one call site: the helper is inlined where it is called)
        run = front_end[f] - node_i[x, CHILD] if front_end[f] > x + 1 else 0
        total = np.float64(0.0)
        for k in range(run + 1):
            total += _refit_node(vertices, node, node_i, leaf_faces, verts, front_end[f] - 1 - k if k < run else x)
        part[f] = total
    for g in range(roots.shape[0]):                    # a few nodes a tree: not worth a parallel region
        total = np.float64(0.0)
        for f in range(front_start[g], front_start[g + 1]):
            total += part[f]
        for k in range(tops_start[g], tops_start[g + 1]):
            i = tops[k]                                # inner nodes: their children's union
            if i < 0:
                break
            _union_children(node, node_i, i)
            total += np.float64(C_TRAVERSE) * np.float64(_area(node[i, 0], node[i, 1], node[i, 2],
                                                               node[i, 3], node[i, 4], node[i, 5]))
        root = roots[g]
        root_area = np.float64(_area(node[root, 0], node[root, 1], node[root, 2],
                                     node[root, 3], node[root, 4], node[root, 5]))
        cost[g] = np.float32(total / root_area) if root_area > 0 else np.float32(0.0)
