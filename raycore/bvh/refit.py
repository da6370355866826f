"""The BVH's refit: every frame, the boxes of trees built once are
recomputed bottom-up from the triangles' positions now (nodes in reverse
order, since children always follow their parent), with the trees' SAH cost,
so that bvh/scene.py rebuilds a tree only when its cost has grown past a
threshold measured against the cost at its last build."""
import numpy as np
from numba import prange

from raycore.bvh.nodes import C_INTERSECT, C_TRAVERSE, CHILD, COUNT, half_area
from raycore.jit.floats import INF
from raycore.jit.presets import helper, parallel_kernel

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
            seen[x] = (inner, int(child[x]), descendants_end.py_func(child, count, x) if inner else x + 1)
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
def descendants_end(child, count, x):
    """One past the last descendant of inner node x (see refit_plan)."""
    while True:
        c = int(child[x])
        if count[c + 1] <= 0 and child[c + 1] >= 0:
            x = c + 1
        elif count[c] <= 0 and child[c] >= 0:
            x = c
        else:
            return c + 2


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
    a = np.float64(half_area(node[i, 0], node[i, 1], node[i, 2], node[i, 3], node[i, 4], node[i, 5]))
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
            total += np.float64(C_TRAVERSE) * np.float64(half_area(node[i, 0], node[i, 1], node[i, 2],
                                                               node[i, 3], node[i, 4], node[i, 5]))
        root = roots[g]
        root_area = np.float64(half_area(node[root, 0], node[root, 1], node[root, 2],
                                     node[root, 3], node[root, 4], node[root, 5]))
        cost[g] = np.float32(total / root_area) if root_area > 0 else np.float32(0.0)
