"""An instanced world behind the accelerators' common surface
(accelerators.py): camera, shadow and batch rays through the top level and
the prototypes' trees (instancing/walk.py). Its hits carry the instance
(Hits.inst) besides the triangle; instancing/seen.py places the seen
triangles in the world for the gather."""
import numpy as np

from raycore.grid.trace import Hits, row_major_offsets
from raycore.instancing.walk import (world_light_visibility, world_sample_visibility, world_trace_camera,
                                     world_trace_rays)
from raycore.jit.counters import Counters
from raycore.jit.workspace import scratch


class InstancedAccel:
    """The frame's top level (top), trees and Placement (instancing/world.py)."""
    name = "bvh"
    packet = 8          # camera packets are 8x8 pixels, as the BVH's

    def __init__(self, top, trees, place, workspace=None):
        self.top, self.trees, self.place, self.workspace = top, trees, place, workspace
        self.world = (top, trees, place.tree, place.inverse, place.origin)

    def trace_camera(self, cam, width, height, jitter):
        n = width * height
        w = self.workspace
        out = (scratch(w, "world.t", n), scratch(w, "world.prim", n, np.int32), scratch(w, "world.inst", n, np.int32),
               scratch(w, "world.b1", n), scratch(w, "world.b2", n))
        c = world_trace_camera(self.world, cam, width, height, jitter, out)
        t, prim, inst, b1, b2 = out
        return Hits(t, prim, b1, b2, Counters.of(c), inst), row_major_offsets(width, height)

    def trace_shadows(self, rays, vis) -> Counters:
        return Counters.of(world_light_visibility(self.world, rays, vis))

    def trace_lights(self, surface, lights, rows, vis, skip=None):
        n, c = world_sample_visibility(self.world, surface, lights, rows, vis, skip)
        return Counters.of(c), n

    def trace_rays(self, origins, dirs, t_min=None, t_max=None, any_hit=False) -> Hits:
        t, prim, inst, b1, b2, c = world_trace_rays(self.world, origins, dirs, t_min, t_max, any_hit)
        return Hits(t, prim, b1, b2, Counters.of(c), inst)
