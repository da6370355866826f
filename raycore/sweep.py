"""A camera pass's hits turned into pixels in one sweep, block by block:
gather a 32x32-pixel block's visible samples, trace their shadow rays
through the BVH, shade them and write the block's pixels, while the
block's rows (~110 KB for 1,024 samples) stay in the core's cache.

The phase by phase path (surface.visible_surface, then the shadow pass,
shade.shade_samples, shade.write_pixels) writes every sample's 26 values
to memory and reads them back three times: ~270 bytes a sample, ~130 MB
a frame on hand, at the ~9 GB/s the two cores of this machine kind write.
Here each stage is the same compiled function that path calls (fill_block,
shade_rows, write_block; the shadow rays' bvh/trace.trace_block_lights_into
shares its packets, _light_packet, with that path's trace_light_samples),
called once a block on buffers of the block's size.

The frame takes this sweep for a pass whose samples need nothing else:
shadows through the BVH (or none), every lit light traced for every sample
(no area light's other emitters waiting for its probes) and no AOVs; the
error budget's later passes, grid and kd-tree shadows and AOVs keep the
phase by phase path. The sweep's time is split between the shadow and
shade phases by the cycle counter (each thread counts the cycles it spent
tracing shadow rays against all its cycles in the sweep).
"""
from typing import NamedTuple

import numba
import numpy as np
from numba import prange

from raycore.jit.presets import cycle_count, kernel, parallel_kernel
from raycore.bvh.nodes import empty_bvh
from raycore.bvh.trace import block_lights_entry, scratch
from raycore.config import EPS_OFFSET_ULPS
from raycore.jit.counters import N_COUNTERS
from raycore.jit.launch import call_native, on_omp_threads
from raycore.shading.shade import shade_rows, write_block
from raycore.config import GATHER_BLOCK
from raycore.shading.surface import fill_block
from raycore.jit.tile_queue import new_queue, next_tile, tile_corner, tile_count

F32 = np.float32
# worker statistics: cycles in the sweep, cycles tracing shadow rays, active shadow rays, visible samples
TOTAL, SHADOW, LIVE, SAMPLES = 0, 1, 2, 3
NO_BVH = empty_bvh(1, 0)            # the tree's stand-in when there are no shadow rays


@kernel
def shade_blocks(cam, jx, jy, hit_t, hit_prim, hit_b1, hit_b2, row_off, col_off, tri_verts, faces, normals,
                 tri_material, materials, uvs, tex_data, tex_info, bvh, lights, shadow_lights, rows,
                 offset_ulps, shadows, shadow_entry, ambient, bg, weight, accumulate, queue, rgba, z, counters,
                 stats):
    """One thread's share of a camera pass's pixels (shade_image starts one
    per thread, shade_blocks_on_threads): GATHER_BLOCK^2-pixel blocks pulled from `queue` until none
    are left, each gathered (hits of pixel (x, y) at row_off[y] +
    col_off[x]), shadowed (when shadows: lights shadow_lights (m, 4) into
    vis rows `rows`, as bvh/trace.trace_light_samples, through
    trace_block_lights_into at address shadow_entry), shaded with every
    light of `lights` (shading/shade.py's table) and written into rgba (H*W, 4) and
    z (H*W,) as shade.write_pixels does, on this thread's buffers. stats
    (4,): this worker's TOTAL and SHADOW cycles, LIVE shadow rays and
    visible SAMPLES; counters (n_blocks, N_COUNTERS), a row a block."""
    start = cycle_count()
    width = col_off.shape[0]
    # typed int64, not as literals: the stages then share their compiled
    # specialisations with the phase by phase path's calls
    block = np.int64(GATHER_BLOCK)
    zero = np.int64(0)
    blocks_x, n_blocks = tile_count(width, row_off.shape[0], block)
    m = GATHER_BLOCK * GATHER_BLOCK
    found = np.empty((4, m + 1), np.int64)
    pixel = np.empty(m, np.int32)
    prim = np.empty(m, np.int32)
    point = np.empty((3, m), F32)
    lifted = np.empty((3, m), F32)
    geo_n = np.empty((3, m), F32)
    smooth_n = np.empty((3, m), F32)
    view = np.empty((3, m), F32)
    depth = np.empty(m, F32)
    mag = np.empty(m, F32)
    albedo = np.empty((3, m), F32)
    ks = np.empty(m, F32)
    shininess = np.empty(m, F32)
    # rows of unlit lights stay 0 (they are never traced)
    vis = np.zeros((lights.shape[0], m if shadows else 0), F32)
    rgb = np.empty((3, m), F32)
    spec_w = np.empty(m, F32)
    cos_h = np.empty(m, F32)
    ray, h_t, h_b1, h_b2, prim_r, ia, planes, stack = scratch()
    live = np.zeros(1, np.int64)
    while True:
        b = next_tile(queue, n_blocks)
        if b < 0:
            break
        n = fill_block(cam, jx, jy, hit_prim, hit_b1, hit_b2, hit_t, row_off, col_off, block, b, blocks_x,
                       tri_verts, faces, normals, tri_material, materials, uvs, tex_data, tex_info, zero,
                       found, pixel, prim, point, lifted, geo_n, smooth_n, view, depth, mag, albedo, ks, shininess)
        stats[SAMPLES] += n
        if shadows:
            t0 = cycle_count()
            # through its address, so that the packet walk is compiled only
            # for frames with shadow rays (linked in, every sweep compiled
            # it: the demo's with --no-shadows 16.6 s against 7.1 now)
            if not call_native(shadow_entry, (bvh, shadow_lights, rows, np.int64(n), lifted, geo_n, smooth_n,
                                              mag, offset_ulps, vis, counters, np.int64(b), ray, h_t, h_b1,
                                              h_b2, prim_r, ia, planes, stack, live)):
                raise MemoryError("shadow rays of a block failed")
            stats[SHADOW] += cycle_count() - t0
        shade_rows(point, smooth_n, view, albedo, ks, shininess, lights, vis, shadows, ambient, zero, n, rgb,
                   spec_w, cos_h)
        x0, y0 = tile_corner(b, blocks_x, block)
        write_block(pixel, rgb, depth, n, x0, y0, block, width, bg, weight, accumulate, rgba, z)
    stats[LIVE] += live[0]
    stats[TOTAL] += cycle_count() - start


@parallel_kernel
def shade_blocks_on_threads(entry, ok, cam, jx, jy, hit_t, hit_prim, hit_b1, hit_b2, row_off, col_off, tri_verts,
                            faces, normals, tri_material, materials, uvs, tex_data, tex_info, bvh, lights,
                            shadow_lights, rows, offset_ulps, shadows, shadow_entry, ambient, bg, weight, accumulate,
                            queue, rgba, z, counters, stats):
    """shade_blocks on each of numba's threads (a row of stats each), called
    through its native entry point (jit/launch.py: nothing linked in, nothing
    optimised twice). ok: a flag a thread, False if its worker failed."""
    for w in prange(stats.shape[0]):
        ok[w] = call_native(entry, (cam, jx, jy, hit_t, hit_prim, hit_b1, hit_b2, row_off, col_off, tri_verts,
                                    faces, normals, tri_material, materials, uvs, tex_data, tex_info, bvh, lights,
                                    shadow_lights, rows, offset_ulps, shadows, shadow_entry, ambient, bg, weight,
                                    accumulate, queue, rgba, z, counters, stats[w]))


class Sweep(NamedTuple):
    """What one shade_image call did."""
    samples: int              # visible samples (camera rays that hit)
    shadow_rays: int          # active shadow rays
    counters: np.ndarray      # (N_COUNTERS,) the shadow packets' counters, summed
    shadow_share: float       # the share of the sweep's time spent tracing shadow rays


def shade_image(cam, jitter, hits, layout, tri_verts, faces, normals, tri_material, materials, uvs, tex_data,
                tex_info, lights, bvh, rows, ambient, bg, weight, accumulate, rgba, z) -> Sweep:
    """One camera pass's hits into the image (see shade_blocks): shadows to
    lights[rows] through `bvh` (None: no shadow rays), shading with every
    row of `lights` (unlit rows are dark)."""
    row_off, col_off = layout
    _, n_blocks = tile_count(col_off.shape[0], row_off.shape[0], GATHER_BLOCK)
    shadows = bvh is not None
    rows = np.asarray(rows if shadows else [], np.int64)
    counters = np.zeros((n_blocks if shadows else 1, N_COUNTERS), np.int64)
    n_workers = numba.get_num_threads()
    stats = np.zeros((n_workers, 4), np.int64)
    queue = new_queue()
    tree = bvh if shadows else NO_BVH
    shadow_lights = np.ascontiguousarray(lights[rows, :4])
    # no shadow rays: the walk is neither called nor compiled
    entry = block_lights_entry(tree, shadow_lights, rows, counters) if shadows else 0
    args = (cam, F32(jitter[0]), F32(jitter[1]), hits.t, hits.prim, hits.b1, hits.b2, row_off, col_off, tri_verts,
            faces, normals, tri_material, materials, uvs, tex_data, tex_info, tree, lights, shadow_lights, rows,
            F32(EPS_OFFSET_ULPS), shadows, np.int64(entry), F32(ambient), bg, F32(weight), accumulate, queue, rgba,
            z, counters)
    on_omp_threads(shade_blocks_on_threads, shade_blocks, n_workers, *args, per_worker=stats)
    total = stats[:, TOTAL].sum()
    return Sweep(int(stats[:, SAMPLES].sum()), int(stats[:, LIVE].sum()), counters.sum(axis=0),
                 float(stats[:, SHADOW].sum() / total) if total > 0 else 0.0)


__all__ = ["Sweep", "shade_blocks", "shade_image"]
