"""One light's per-pixel visibility through the grid in one call: the
visible surface of a pass of camera hits, its shadow rays in light-space
order, and their visibility (for tests and tools; the frame calls these
steps apart, through whichever structure it traces shadows with)."""
import numpy as np

from raycore.geometry.light_rays import SHADOW_PACKET, LightRays
from raycore.grid.build import Grid
from raycore.grid.trace import Hits, light_visibility, row_major_offsets
from raycore.shading.surface import Surface, visible_surface

NO_SMOOTH = (np.zeros((0, 3), np.int32), np.zeros((0, 3), np.float32))


def surface_of(hits: Hits, tri_verts, cam, width, height, jitter=(0.5, 0.5), offsets=None,
               smooth=None) -> Surface:
    """The visible Surface of `hits` (row-major, or packet-major with
    `offsets`), untextured, with the default material; `smooth` (faces,
    vertex normals) lifts shadow origins toward the smooth surface."""
    row_off, col_off = offsets if offsets is not None else row_major_offsets(width, height)
    faces, normals = smooth or NO_SMOOTH
    material = np.array([[0.8, 0.8, 0.8, 0, 1, -1, 0, 0]], np.float32)
    return visible_surface(cam, jitter, hits.t, hits.prim, hits.b1, hits.b2, row_off, col_off,
                           tri_verts, faces, normals, np.zeros(tri_verts.shape[0], np.int32),
                           material, np.zeros((0, 2), np.float32), np.zeros(1, np.float32),
                           np.zeros((0, 3), np.int64))


def trace_light(grid: Grid, tri_verts, cam, width, height, hits: Hits, light_kind, light_vec,
                packet=SHADOW_PACKET, jitter=(0.5, 0.5), offsets=None, smooth=None, cull=True):
    """Per-pixel visibility (H*W,) f32 of one light (kind 0 point at
    light_vec, 1 directional along light_vec) from the surface points in
    `hits`, and the counters: surface_of, LightRays and light_visibility in
    one call (for tests and tools; the frame calls them apart)."""
    surface = surface_of(hits, tri_verts, cam, width, height, jitter, offsets, smooth)
    vis_s, counters = light_visibility(grid, tri_verts, LightRays(surface, light_kind, light_vec),
                                       packet=packet, cull=cull)
    vis = np.zeros(width * height, np.float32)
    vis[surface.pixel] = vis_s
    return vis, counters
