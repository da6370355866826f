"""The BVH's node layout and its SAH costs, shared by the build, the refit
and the traversal.

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
"""
from typing import NamedTuple

import numpy as np

from raycore.jit.presets import kernel

# SAH constants: a node visit of a packet (its frustum test, a box test of
# one or more 16-ray chunks, the stack) costs about three ray/triangle tests
# of a chunk (~200 cycles against ~40-70 on this machine kind's shadow
# packets). With C_TRAVERSE 3 instead of 1 the trees have larger leaves and
# a shadow packet visits 15-30 % fewer nodes (docs/performance.md).
# Leaves up to MAX_LEAF triangles.
MAX_LEAF = 8
C_TRAVERSE = np.float32(3.0)
C_INTERSECT = np.float32(1.0)
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
    """Arrays for n_nodes nodes and n_refs references, left unwritten: a
    tree over m triangles is given 2m nodes and uses about a third of them
    (MAX_LEAF triangles a leaf); pages never written take no memory."""
    node = np.empty((n_nodes, 8), np.float32)
    return Bvh(node, node.view(np.int32), np.empty(n_refs, np.int32), np.empty((n_refs, 9), np.float32))


@kernel
def half_area(x0, y0, z0, x1, y1, z1):
    """Half the surface area of the box (x0, y0, z0)-(x1, y1, z1): the SAH's measure."""
    dx = max(x1 - x0, np.float32(0.0))
    dy = max(y1 - y0, np.float32(0.0))
    dz = max(z1 - z0, np.float32(0.0))
    return dx * dy + dy * dz + dz * dx
