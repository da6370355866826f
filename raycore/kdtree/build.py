"""SAH kd-tree, rebuilt every frame (binned SAH, Wald & Havran 2006 style).

Flat arrays, no pointers: node i is inner when axis[i] < 3 (children at
child[i] and child[i] + 1, below and above `split[i]`), or a leaf (axis 3)
listing count[i] triangle ids from refs[child[i]]. A triangle whose
bounding box touches the split plane goes to both sides (<= and >=), so a
triangle lying in the plane is in both children and no ray can slip between.

The build is one loop over a stack of nodes. For each node the triangles'
boxes (clipped to the node) are binned along each axis; the surface area
heuristic picks the plane. Cost constants are measured, not the textbook
ratio: a packet's node visit (frustum/box tests for 64 rays) costs about five
of its vectorized ray/triangle tests. On the hand and runner scenes, the usual
C_T = 1, C_I = 1.5 with an empty-side bonus built 7-12 references per
triangle in 114 / 927 ms and traced slower (52 / 201 ms at 512^2) than
C_T = 1, C_I = 0.2, no bonus, leaves up to 8 triangles: 2.7 references per
triangle, 17 / 82 ms, 26 / 57 ms (see the issue note for the sweep).
"""
from typing import NamedTuple

import numpy as np

from raycore.jit.presets import kernel
from raycore.config import EPS_KD_BOX_REL

N_BINS = 32
C_TRAVERSE = np.float32(1.0)
C_INTERSECT = np.float32(0.2)
EMPTY_BONUS = np.float32(1.0)
LEAF_SIZE = 8
LEAF = 3


class KdTree(NamedTuple):
    lo: np.ndarray        # (3,) f32 root box
    hi: np.ndarray
    axis: np.ndarray      # (n_nodes,) i32: 0..2 inner, 3 leaf
    split: np.ndarray     # (n_nodes,) f32
    child: np.ndarray     # (n_nodes,) i32: first child (inner) or first ref (leaf)
    count: np.ndarray     # (n_nodes,) i32: triangles in a leaf
    refs: np.ndarray      # (n_refs,) i32 triangle ids (leaf lists live here)
    depth: int


@kernel
def _grow(a, need):
    """a, or a copy with at least `need` slots (capacity doubles). Copied
    by a loop: a slice assignment (b[:n] = a) compiles numba's message for
    mismatched shapes, string formatting of the shapes, 2.4 of the build's 5.4 s."""
    if need <= a.shape[0]:
        return a
    b = np.empty(max(need, 2 * a.shape[0]), a.dtype)
    for i in range(a.shape[0]):
        b[i] = a[i]
    return b


@kernel
def _build(boxes, lo, hi, max_depth, c_trav, c_isect, bonus, leaf_size):
    n = boxes.shape[0]
    cap_nodes = max(16, 4 * n // leaf_size)
    axis = np.empty(cap_nodes, np.int32)
    split = np.empty(cap_nodes, np.float32)
    child = np.empty(cap_nodes, np.int32)
    count = np.empty(cap_nodes, np.int32)
    refs = np.empty(max(16, 4 * n), np.int32)
    for i in range(n):
        refs[i] = i
    n_refs = n
    n_nodes = 1
    # stack rows: node, ref start, ref count, depth; boxes in stack_box
    stack = np.empty((max_depth + 2, 4), np.int64)
    stack_box = np.empty((max_depth + 2, 6), np.float32)
    stack[0, 0], stack[0, 1], stack[0, 2], stack[0, 3] = 0, 0, n, 0
    for a in range(3):
        stack_box[0, a] = lo[a]
        stack_box[0, 3 + a] = hi[a]
    top = 1
    deepest = 0
    starts = np.zeros(N_BINS, np.int64)
    ends = np.zeros(N_BINS, np.int64)
    while top > 0:
        top -= 1
        node, r0, m, depth = stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3]
        b = stack_box[top].copy()
        deepest = max(deepest, depth)
        best_cost = c_isect * np.float32(m)
        best_axis = -1
        best_pos = np.float32(0.0)
        if m > leaf_size and depth < max_depth:
            ex, ey, ez = b[3] - b[0], b[4] - b[1], b[5] - b[2]
            area = ex * ey + ey * ez + ez * ex
            for a in range(3):
                ext = b[3 + a] - b[a]
                if not ext > 0:
                    continue
                starts[:] = 0
                ends[:] = 0
                scale = np.float32(N_BINS) / ext
                for k in range(r0, r0 + m):
                    t = refs[k]
                    lo_a = max(boxes[t, a], b[a])
                    hi_a = min(boxes[t, 3 + a], b[3 + a])
                    i0 = min(max(int((lo_a - b[a]) * scale), 0), N_BINS - 1)
                    i1 = min(max(int((hi_a - b[a]) * scale), 0), N_BINS - 1)
                    starts[i0] += 1
                    ends[i1] += 1
                u = (a + 1) % 3
                v = (a + 2) % 3
                eu, ev = b[3 + u] - b[u], b[3 + v] - b[v]
                n_left = 0
                n_right = m
                for k in range(1, N_BINS):
                    n_left += starts[k - 1]
                    n_right -= ends[k - 1]
                    pos = b[a] + ext * np.float32(k) / np.float32(N_BINS)
                    wl = pos - b[a]
                    wr = b[3 + a] - pos
                    area_l = wl * eu + eu * ev + ev * wl
                    area_r = wr * eu + eu * ev + ev * wr
                    cost = c_trav + c_isect * (area_l * n_left + area_r * n_right) / area
                    if n_left == 0 or n_right == 0:
                        cost *= bonus
                    if cost < best_cost:
                        best_cost, best_axis, best_pos = cost, a, pos
        if best_axis < 0:                               # leaf
            axis[node] = LEAF
            child[node] = r0
            count[node] = m
            continue
        a = best_axis
        # children's refs go to the end of `refs`: below, then above
        refs = _grow(refs, n_refs + 2 * m)
        left0 = n_refs
        for k in range(r0, r0 + m):
            t = refs[k]
            if max(boxes[t, a], b[a]) <= best_pos:
                refs[n_refs] = t
                n_refs += 1
        right0 = n_refs
        for k in range(r0, r0 + m):
            t = refs[k]
            if min(boxes[t, 3 + a], b[3 + a]) >= best_pos:
                refs[n_refs] = t
                n_refs += 1
        if n_nodes + 2 > axis.shape[0]:
            axis = _grow(axis, n_nodes + 2)
            split = _grow(split, n_nodes + 2)
            child = _grow(child, n_nodes + 2)
            count = _grow(count, n_nodes + 2)
        first = n_nodes
        n_nodes += 2
        axis[node] = a
        split[node] = best_pos
        child[node] = first
        count[node] = 0
        for side in range(2):
            stack[top, 0] = first + side
            stack[top, 1] = left0 if side == 0 else right0
            stack[top, 2] = (right0 - left0) if side == 0 else (n_refs - right0)
            stack[top, 3] = depth + 1
            for q in range(6):
                stack_box[top, q] = b[q]
            if side == 0:
                stack_box[top, 3 + a] = best_pos
            else:
                stack_box[top, a] = best_pos
            top += 1
    return axis[:n_nodes], split[:n_nodes], child[:n_nodes], count[:n_nodes], refs[:n_refs], deepest


@kernel
def triangle_boxes(tri_verts, boxes):
    """(n, 6) lo/hi boxes of the triangles; a non-finite triangle gets an
    empty box (lo > hi) and so never enters a leaf's interior bins."""
    for t in range(tri_verts.shape[0]):
        ok = True
        for k in range(9):
            if not np.isfinite(tri_verts[t, k]):
                ok = False
        for a in range(3):
            x0, x1, x2 = tri_verts[t, a], tri_verts[t, 3 + a], tri_verts[t, 6 + a]
            boxes[t, a] = min(x0, x1, x2) if ok else np.float32(np.inf)
            boxes[t, 3 + a] = max(x0, x1, x2) if ok else np.float32(-np.inf)


PARALLEL_MIN = 20000       # below this many triangles one thread builds it all


def _leaf_boxes(axis, split, child, lo, hi):
    """{leaf node: (depth, box lo, box hi)} of a (small) tree."""
    out, stack = {}, [(0, 0, lo.copy(), hi.copy())]
    while stack:
        node, depth, blo, bhi = stack.pop()
        if axis[node] == LEAF:
            out[node] = (depth, blo, bhi)
            continue
        a, sp = axis[node], split[node]
        below_hi, above_lo = bhi.copy(), blo.copy()
        below_hi[a], above_lo[a] = sp, sp
        stack += [(child[node], depth + 1, blo, below_hi), (child[node] + 1, depth + 1, above_lo, bhi)]
    return out


def _build_parallel(boxes, lo, hi, max_depth, params, threads):
    """The top levels on one thread, then each subtree the depth limit cut
    off on its own thread (numba releases the GIL), stitched into one tree.
    Same splits as a sequential build: SAH decisions do not depend on the
    depth limit, and each subtree sees exactly its node's triangles and box."""
    from concurrent.futures import ThreadPoolExecutor
    top_depth = max(1, int(np.ceil(np.log2(threads * 4))))
    axis, split, child, count, refs, _ = _build(boxes, lo, hi, top_depth, *params)
    leaves = _leaf_boxes(axis, split, child, lo, hi)
    jobs = [(node, d, blo, bhi) for node, (d, blo, bhi) in sorted(leaves.items())
            if d == top_depth and count[node] > params[3]]

    def run(job):
        node, d, blo, bhi = job
        ids = refs[child[node]:child[node] + count[node]].copy()
        return ids, _build(boxes[ids], blo.astype(np.float32), bhi.astype(np.float32), max_depth - d, *params)

    with ThreadPoolExecutor(threads) as pool:
        results = list(pool.map(run, jobs))
    axis_l, split_l, child_l, count_l = [axis.copy()], [split.copy()], [child.copy()], [count.copy()]
    refs_l = [refs]
    n_nodes, n_refs, deepest = len(axis), len(refs), top_depth
    top = (axis_l[0], split_l[0], child_l[0], count_l[0])
    for (node, d, _, _), (ids, (s_axis, s_split, s_child, s_count, s_refs, s_depth)) in zip(jobs, results):
        base = n_nodes - 1                      # subtree node i >= 1 goes to base + i
        s_child = s_child.copy()
        inner = s_axis != LEAF
        s_child[inner] += base
        s_child[~inner] += n_refs
        # the subtree's root takes the place of the cut-off leaf
        top[0][node], top[1][node], top[2][node], top[3][node] = s_axis[0], s_split[0], s_child[0], s_count[0]
        axis_l.append(s_axis[1:])
        split_l.append(s_split[1:])
        child_l.append(s_child[1:])
        count_l.append(s_count[1:])
        refs_l.append(ids[s_refs].astype(np.int32))
        n_nodes += len(s_axis) - 1
        n_refs += len(s_refs)
        deepest = max(deepest, d + s_depth)
    return (np.concatenate(axis_l), np.concatenate(split_l), np.concatenate(child_l),
            np.concatenate(count_l), np.concatenate(refs_l), deepest)


def build_kdtree(tri_verts: np.ndarray, max_depth: int = 0, c_traverse=C_TRAVERSE,
                 c_intersect=C_INTERSECT, empty_bonus=EMPTY_BONUS, leaf_size=LEAF_SIZE,
                 threads: int = 0) -> KdTree:
    """SAH kd-tree over tri_verts (n, 9) f32; max_depth 0 = 8 + 1.3 log2(n);
    threads 0 = numba's thread count (subtrees are built in parallel)."""
    import numba
    n = tri_verts.shape[0]
    boxes = np.empty((n, 6), np.float32)
    triangle_boxes(tri_verts, boxes)
    finite = boxes[:, 0] <= boxes[:, 3]
    if finite.any():
        lo = boxes[finite, :3].min(axis=0)
        hi = boxes[finite, 3:].max(axis=0)
    else:
        lo, hi = np.zeros(3, np.float32), np.ones(3, np.float32)
    pad = EPS_KD_BOX_REL * (np.abs(np.concatenate([lo, hi])).max() + np.float32(1e-30))
    lo, hi = (lo - pad).astype(np.float32), (hi + pad).astype(np.float32)
    if max_depth <= 0:
        max_depth = int(8 + 1.3 * np.log2(max(n, 1)))
    params = (np.float32(c_traverse), np.float32(c_intersect), np.float32(empty_bonus), int(leaf_size))
    threads = threads or numba.get_num_threads()
    if threads > 1 and n >= PARALLEL_MIN and max_depth > 4:
        axis, split, child, count, refs, depth = _build_parallel(boxes, lo, hi, max_depth, params, threads)
    else:
        axis, split, child, count, refs, depth = _build(boxes, lo, hi, max_depth, *params)
    # a non-finite triangle would sit in every leaf: drop it from the lists
    if not finite.all():
        keep = finite[refs]
        new_start = np.concatenate([[0], np.cumsum(keep)]).astype(np.int32)
        leaf = axis == LEAF
        child = child.copy()
        count = count.copy()
        ends = child[leaf] + count[leaf]
        child[leaf] = new_start[child[leaf]]
        count[leaf] = new_start[ends] - child[leaf]
        refs = refs[keep]
    return KdTree(lo, hi, axis, split, child, count, np.ascontiguousarray(refs, np.int32), int(depth))
