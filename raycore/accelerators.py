"""One surface for every acceleration structure, as trimesh's ray backends
share one: `trace_camera`, `trace_shadows` and `trace_rays` with the same
arguments and the same results, so that the frame (frame.py) picks its
structure once and never asks which one it has.

  GridAccel  the per-frame uniform grid: camera packets by Coherent Grid
             Traversal (grid/drivers.py), shadow rays in light-space packets
             (geometry/light_rays.py), ray batches in packets;
  KdAccel    the SAH kd-tree: camera packets by MLRTA frustum traversal,
             shadow rays and batches one by one (kdtree/packets.py, kdtree/rays.py);
  BvhAccel   the per-frame BVH (refit trees per object under a top level,
             bvh/scene.py): every kind of ray in packets (8x8 camera rays, 128
             shadow or batch rays) that share an
             origin or a direction (bvh/packets.py, bvh/trace.py).

Counters are named (counters.Counters): `visits` are grid cells or tree
nodes, and `candidates` are triangles surviving the grid's culling or the
leaves a tree's packets reached.
"""
import numpy as np

from raycore.bvh.nodes import Bvh
from raycore.bvh.trace import bvh_light_visibility, bvh_sample_visibility, bvh_trace_camera, bvh_trace_rays
from raycore.jit.counters import Counters
from raycore.grid.build import Grid
from raycore.kdtree.build import KdTree
from raycore.kdtree.packets import kd_trace_camera
from raycore.kdtree.rays import kd_light_visibility, kd_trace_rays
from raycore.grid.trace import Hits, camera_buffers, light_visibility, row_major_offsets, trace_camera, trace_rays
from raycore.jit.workspace import scratch

# the kd-tree's camera packets are always KD_PACKET^2 rays
KD_PACKET = 8


class GridAccel:
    """The uniform grid of this frame (grid/build.Grid) over tri_verts."""
    name = "grid"

    def __init__(self, grid: Grid, tri_verts, packet: int, cull=True, buffers=None):
        self.grid, self.tri_verts, self.packet, self.cull = grid, tri_verts, packet, cull
        self.buffers = buffers

    def trace_camera(self, cam, width, height, jitter):
        """(Hits, (row_off, col_off)): hit of pixel (x, y) at row_off[y] + col_off[x]."""
        if self.buffers is None or self.buffers.key != (width, height, self.packet):
            self.buffers = camera_buffers(width, height, self.packet)
        hits = trace_camera(self.grid, self.tri_verts, cam, width, height, self.packet, jitter,
                            self.buffers, row_major=False, cull=self.cull)
        return hits._replace(counters=Counters.of(hits.counters)), (self.buffers.row_off, self.buffers.col_off)

    def trace_shadows(self, rays, vis) -> Counters:
        """vis[i] = 1 where shadow ray i (geometry/light_rays.LightRays) reaches its light, else 0."""
        _, c = light_visibility(self.grid, self.tri_verts, rays, vis, cull=self.cull)
        return Counters.of(c)

    def trace_rays(self, origins, dirs, t_min=None, t_max=None, any_hit=False) -> Hits:
        h = trace_rays(self.grid, self.tri_verts, origins, dirs, t_min, t_max, any_hit=any_hit)
        return h._replace(counters=Counters.of(h.counters))


class KdAccel:
    """An SAH kd-tree (kdtree/build.KdTree) over tri_verts."""
    name = "kdtree"
    packet = KD_PACKET

    def __init__(self, tree: KdTree, tri_verts):
        self.tree, self.tri_verts = tree, tri_verts

    def trace_camera(self, cam, width, height, jitter):
        hits = Hits(*kd_trace_camera(self.tree, self.tri_verts, cam, width, height, KD_PACKET, jitter))
        return hits._replace(counters=Counters.of(hits.counters)), row_major_offsets(width, height)

    def trace_shadows(self, rays, vis) -> Counters:
        _, c = kd_light_visibility(self.tree, self.tri_verts, rays, vis)
        return Counters.of(c)

    def trace_rays(self, origins, dirs, t_min=None, t_max=None, any_hit=False) -> Hits:
        h = Hits(*kd_trace_rays(self.tree, self.tri_verts, origins, dirs, t_min, t_max, any_hit))
        return h._replace(counters=Counters.of(h.counters))


def packet_of(accel: str, grid_packet: int) -> int:
    """The camera-packet side a structure really traces: the grid's is
    chosen (grid_packet), the kd-tree's and the BVH's are fixed."""
    return {"kdtree": KdAccel.packet, "bvh": BvhAccel.packet}.get(accel, grid_packet)


class BvhAccel:
    """The frame's BVH (nodes.Bvh, kept by bvh/scene.SceneBvh) over tri_verts."""
    name = "bvh"
    packet = 8          # camera packets are 8x8 pixels

    def __init__(self, bvh: Bvh, tri_verts, workspace=None):
        self.bvh, self.tri_verts, self.workspace = bvh, tri_verts, workspace

    def trace_camera(self, cam, width, height, jitter):
        n = width * height
        out = (scratch(self.workspace, "bvh.t", n), scratch(self.workspace, "bvh.prim", n, np.int32),
               scratch(self.workspace, "bvh.b1", n), scratch(self.workspace, "bvh.b2", n))
        hits = Hits(*bvh_trace_camera(self.bvh, cam, width, height, jitter, out))
        return hits._replace(counters=Counters.of(hits.counters)), row_major_offsets(width, height)

    def trace_shadows(self, rays, vis) -> Counters:
        _, c = bvh_light_visibility(self.bvh, rays, vis)
        return Counters.of(c)

    def trace_lights(self, surface, lights, rows, vis, skip=None):
        """(Counters, active rays): vis[rows[j], i] = 1 where sample i of a
        camera pass's Surface sees light j (lights (m, 4): kind, x, y, z).
        The shadow rays are made in the packets, in the samples' order,
        with no light-space sort: the gather's 32x32-pixel blocks are
        coherent as they are (docs/accelerators.md). Structures without this
        method get LightRays, a light at a time."""
        n, c = bvh_sample_visibility(self.bvh, surface, lights, rows, vis, skip)
        return Counters.of(c), n

    def trace_rays(self, origins, dirs, t_min=None, t_max=None, any_hit=False) -> Hits:
        h = Hits(*bvh_trace_rays(self.bvh, origins, dirs, t_min, t_max, any_hit))
        return h._replace(counters=Counters.of(h.counters))
