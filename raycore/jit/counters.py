"""The work counters every traversal keeps, by name.

Kernels add into an int64 array (rows: one per tile or packet, so threads
never share a row; columns: the indices below) and callers sum the rows into
a Counters record. The grid and the kd-tree count the same things under the
same names: a visit is a grid cell or a kd-tree node, a candidate a triangle
that survived the grid's mailbox and culling or a kd-tree leaf reached.
"""
from typing import NamedTuple

import numpy as np

PACKETS, VISITS, TESTS, CANDIDATES, FALLBACK_RAYS = 0, 1, 2, 3, 4
N_COUNTERS = 5


class Counters(NamedTuple):
    """Work done by one call, summed over its packets."""
    packets: int
    visits: int          # grid cells / kd-tree nodes visited
    tests: int           # ray-triangle tests
    candidates: int      # grid: triangles past mailbox and culling; kd-tree: leaves visited
    fallback_rays: int   # rays traced one by one (the grid: no common direction; the kd-tree: split to one ray)

    @classmethod
    def of(cls, rows):
        """Counters from a kernel's (rows, N_COUNTERS) array, or its row sums."""
        rows = np.asarray(rows)
        total = rows.sum(axis=0) if rows.ndim == 2 else rows
        return cls(*(int(v) for v in total[:N_COUNTERS]))
