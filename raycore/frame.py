"""One frame, phase by phase: build -> trace -> surface -> shadow -> shade.

Inputs are flat arrays only (no scene-file objects), so `raycore` never needs
`anim`. Each phase is timed apart; the shadow pass is skipped when there are
no lights or shadows are off, the texture path when nothing is textured, and
the AOV writes when none are asked for.
"""
import time
from typing import NamedTuple

import numba
import numpy as np

from raycore.adaptive import camera_rays_of, refine
from raycore.config import ADAPTIVE_SPP_CAP, RenderConfig
from raycore.geometry.light_rays import LightRays
from raycore.geometry.sampling import sample_offsets
from raycore.geometry.shutter_lens import budget_times_lens, plain_times_lens
from raycore.grid.trace import camera_buffers, row_major_offsets
from raycore.jit.counters import Counters
from raycore.jit.thread_pool import on_threads
from raycore.jit.tile_queue import new_queue
from raycore.jit.workspace import Workspace
from raycore.instancing.seen import SeenTriangles
from raycore.instancing.world import InstancedStructures
from raycore.pass_scene import PassScene
from raycore.shading.aovs import NearestAOVs
from raycore.shading.shade import shade_samples, write_pixels
from raycore.shading.surface import Surface, visible_surface
from raycore.structures import FrameStructures
from raycore.sweep import shade_image

__all__ = ["CameraPose", "FrameBuffers", "FrameResult", "Geometry", "Shading", "render_frame"]


class Geometry(NamedTuple):
    """Triangles of one frame (all objects concatenated)."""
    vertices: np.ndarray      # (n_v, 3) f32, this frame's positions
    faces: np.ndarray         # (n_t, 3) i32
    tri_material: np.ndarray  # (n_t,) i32 index into Shading.materials
    uvs: np.ndarray           # (n_v, 2) f32, or (0, 2) when untextured
    vf_start: np.ndarray      # vertex -> faces CSR (see mesh.vertex_face_csr)
    vf_faces: np.ndarray
    instances: object = None  # instancing/world.InstanceFrame: copies of prototypes among the triangles


class Shading(NamedTuple):
    materials: np.ndarray     # (n_mat, 8) f32, see shading/shade.py
    tex_data: np.ndarray      # f32 texels
    tex_info: np.ndarray      # (n_tex, 3) i64
    lights: np.ndarray        # (n_light, 8) f32, see shading/shade.py


class CameraPose(NamedTuple):
    eye: tuple
    look_at: tuple
    up: tuple
    fov: float


class FrameResult(NamedTuple):
    rgba: np.ndarray          # (H, W, 4) f32
    z: np.ndarray             # (H, W) f32, +inf on a miss
    aovs: dict                # name -> (H, W) f32 channels
    timings: dict             # phase -> ms
    counters: dict            # rays, tri_tests, cells, ...
    samples: np.ndarray = None  # (H*W,) i32 samples per pixel, under an error budget only


class FrameBuffers:
    """Per-pixel work arrays kept from frame to frame (same resolution): fresh
    large arrays cost page faults on every frame (~5 ms for a 1024^2 RGBA + Z
    on this machine kind).

    The images a frame returns come from a ring of `n_images` sets: frame k's
    images stay untouched until frame k + n_images is rendered with these
    buffers. A caller that hands images to a writer thread needs a ring larger
    than the number of frames in flight."""

    def __init__(self, width, height, n_lights, packet, n_images=2):
        self.size = (width, height, n_lights, packet)
        self.camera = camera_buffers(width, height, packet)
        self.work = Workspace()
        self.images = [None] * max(1, n_images)
        self.next_image = 0
        self.seen = None

    def seen_triangles(self, n_pix, textured):
        """The work arrays of an instanced world's seen triangles (instancing/seen.py)."""
        if self.seen is None or self.seen.prim.shape[0] < n_pix or (textured and self.seen.uvs.shape[0] == 0):
            self.seen = SeenTriangles(n_pix, textured)
        return self.seen

    def image(self):
        """The next (rgba (H*W, 4), z (H*W,)) f32 pair of the ring."""
        k = self.next_image
        self.next_image = (k + 1) % len(self.images)
        if self.images[k] is None:
            W, H = self.size[:2]
            self.images[k] = (aligned_empty((H * W, 4)), aligned_empty(H * W))
        return self.images[k]


def aligned_empty(shape, dtype=np.float32, align=64):
    """np.empty whose data starts at a multiple of `align` bytes: the block
    write's streaming stores (shade.write_block) need its rows on 32-byte
    boundaries, and numpy's large arrays start 16 bytes past one."""
    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape)) * dtype.itemsize
    raw = np.empty(nbytes + align, np.uint8)
    skip = (-raw.ctypes.data) % align
    return raw[skip:skip + nbytes].view(dtype).reshape(shape)


def light_groups(lights, lit):
    """The lit rows of the light table in groups: one group per area light
    (its emitter rows, column 7 = its group number > 0), one row alone else."""
    groups, by_id = [], {}
    for li in lit:
        gid = int(lights[li, 7])
        if gid > 0 and gid in by_id:
            by_id[gid].append(li)
        else:
            groups.append([li])
            if gid > 0:
                by_id[gid] = groups[-1]
    return groups


def probe_rows(rows, n_probes):
    """The emitters traced for every point first: the group's first n_probes
    (its emitters come in mirrored pairs, whose every prefix spreads over
    the whole light: anim/area_lights.py), or all of them when probing is
    off or pointless."""
    if n_probes <= 0 or n_probes >= len(rows):
        return list(rows)
    return list(rows[:n_probes])


def lit_rows(lights) -> list:
    """The rows of the light table that add light: a light of zero colour *
    intensity adds nothing and costs no ray."""
    return [li for li in range(lights.shape[0]) if np.any(lights[li, 4:7] > 0)]


def sweeps_in_one(cfg: RenderConfig, lights, n_faces: int, instanced=False) -> bool:
    """Whether a frame's camera passes go to pixels in one sweep (sweep.py):
    no AOVs, no instances (whose seen triangles are placed between the
    trace and the gather), and no shadows, or BVH shadows whose every ray
    is traced for every sample (no area light's emitters waiting for its
    probes). Else each pass goes phase by phase (gather, shadows, shading,
    pixels)."""
    if cfg.aovs or instanced:
        return False
    lit = lit_rows(lights)
    if not (cfg.shadows and lit and n_faces > 0):
        return True
    return cfg.shadow_structure == "bvh" and all(
        len(rows) == len(probe_rows(rows, cfg.light_probes)) for rows in light_groups(lights, lit))


def adaptive_cap(cfg: RenderConfig) -> int:
    """The most samples a pixel gets under an error budget: spp, or
    ADAPTIVE_SPP_CAP when spp is 1."""
    return cfg.spp if cfg.spp > 1 else ADAPTIVE_SPP_CAP


def render_frame(geom: Geometry, shading: Shading, pose: CameraPose, cfg: RenderConfig,
                 buffers: FrameBuffers = None, structures: FrameStructures = None,
                 camera_accel=None, shadow_accel=None, motion=None) -> FrameResult:
    """Render one frame. Pass the same `buffers` and `structures` for
    consecutive frames to reuse work arrays, image memory and static geometry;
    the returned images then belong to the buffers' ring (see FrameBuffers),
    else they are fresh arrays.

    Per pass of camera rays (one per sample offset): trace, gather the visible
    surface once (shading/surface.py), trace each light's shadow rays
    (geometry/light_rays.py) through cfg.shadow_structure, shade the samples,
    scatter them into the image; or all of that block by block in one sweep
    (sweep.py, sweeps_in_one).

    motion: under motion blur, u -> (vertices, CameraPose) at shutter
    position u in [0, 1] (geom and pose are those of the frame's own time);
    each pass then takes its own time (geometry/shutter_lens.py). None:
    nothing moves within the frame.

    camera_accel, shadow_accel: objects with the accelerators' methods used
    for the camera or shadow rays instead of building cfg.accel or the
    shadow structure (the compile helper's stand-ins,
    anim/render/compile_helper.py)."""
    return FrameRender(geom, shading, pose, cfg, buffers, structures, camera_accel, shadow_accel, motion).run()


class FrameRender:
    """One frame's passes and their bookkeeping (timings, counters)."""

    def __init__(self, geom, shading, pose, cfg, buffers, structures, camera_accel, shadow_accel, motion):
        W, H = cfg.width, cfg.height
        n_lights = shading.lights.shape[0]
        if buffers is None or buffers.size != (W, H, n_lights, cfg.packet):
            buffers = FrameBuffers(W, H, n_lights, cfg.packet, n_images=1)
        self.geom, self.shading, self.cfg, self.buffers, self.motion = geom, shading, cfg, buffers, motion
        self.n_lights = n_lights
        self.timings = {"build_ms": 0.0, "trace_ms": 0.0, "shadow_ms": 0.0, "shade_ms": 0.0}
        self.counters = {"rays": 0, "shadow_rays": 0, "shadow_rays_skipped": 0, "lights_skipped": 0,
                         "tri_tests": 0, "cells": 0, "fallback_rays": 0,
                         "primary_packets": 0, "primary_visits": 0, "primary_tests": 0, "builds": 0, "passes": 0}
        if structures is None and geom.instances is not None:
            structures = InstancedStructures(geom.faces, len(geom.vertices), geom.vf_start, geom.vf_faces,
                                             geom.instances.ranges, geom.instances.moving)
        elif structures is None:
            structures = FrameStructures(geom.faces, len(geom.vertices), geom.vf_start, geom.vf_faces,
                                         cfg.grid_density)
        self.lit = lit_rows(shading.lights)
        self.counters["lights_skipped"] = n_lights - len(self.lit)
        self.cast_shadows = cfg.shadows and len(self.lit) > 0 and geom.faces.shape[0] > 0
        # the structures are chosen here, once: everything below goes through
        # their common surface (accelerators.py)
        names = (({cfg.shadow_structure} if self.cast_shadows and shadow_accel is None else set())
                 | ({cfg.accel} if camera_accel is None else set()))
        self.scene = PassScene(names, geom, pose, cfg, structures, buffers, self.counters, self.timings, motion,
                               camera_accel, shadow_accel)
        self.bg = np.asarray(cfg.background, np.float32)
        self.aovs = NearestAOVs(cfg.aovs, W * H) if cfg.aovs else None
        # the lights in groups (an area light's emitters together) and the rows
        # traced for every sample first (each group's probes)
        self.groups = ([(rows, probe_rows(rows, cfg.light_probes)) for rows in light_groups(shading.lights, self.lit)]
                       if self.cast_shadows else [])
        self.first_rows = [li for _, probes in self.groups for li in probes]
        self.one_sweep = sweeps_in_one(cfg, shading.lights, geom.faces.shape[0], geom.instances is not None)

    def run(self) -> FrameResult:
        cfg, W, H = self.cfg, self.cfg.width, self.cfg.height
        # under an error budget the image starts from the pixel centres, and spp
        # is the most samples a pixel may get (adaptive.py)
        offsets = sample_offsets(1 if cfg.max_error > 0 else cfg.spp)
        single = len(offsets) == 1
        # one sample: the pass writes the image; several: each adds 1/spp of its own
        rgba, z = self.buffers.image()
        if not single:
            rgba.fill(0.0)
            z.fill(np.inf)
        for jitter, sample in zip(offsets, plain_times_lens(len(offsets))):
            self.camera_pass(jitter, sample, 1.0 / len(offsets), not single, rgba, z)
        samples = None
        counters = self.counters
        if cfg.max_error > 0 and single:
            samples = self.refine_pixels(rgba, z)
            counters["adaptive_spp_mean"] = float(samples.mean())
            counters["spp_cap"] = adaptive_cap(cfg)
            counters["rays_left_out"] = adaptive_cap(cfg) * W * H - counters["rays"]
        if self.motion is not None or cfg.aperture_radius > 0:
            counters["time_samples"] = len(self.scene.times_seen) if self.motion is not None else 1
            counters["lens_samples"] = len(self.scene.lens_seen) if cfg.aperture_radius > 0 else 1
        return FrameResult(rgba.reshape(H, W, 4), z.reshape(H, W), self.aovs.channels(H, W) if self.aovs else {},
                           self.timings, counters, samples)

    def camera_pass(self, jitter, sample, weight, accumulate, rgba, z):
        """One pass of camera rays at sub-pixel offset `jitter` and (time,
        lens) `sample`, its samples written into (or with `accumulate`,
        added to) the image with `weight`."""
        scene, geom, shading, timings, W, H = self.scene, self.geom, self.shading, self.timings, \
            self.cfg.width, self.cfg.height
        scene.move_to(sample)
        t0 = time.perf_counter()
        hits, layout = scene.accel.trace_camera(scene.cam, W, H, jitter)
        timings["trace_ms"] += (time.perf_counter() - t0) * 1e3
        c = hits.counters
        self.count_camera_rays(W * H, c)
        # primary rays alone (grid: cells; kd-tree: nodes), for `frustrace compare`
        self.counters["primary_packets"] += c.packets
        self.counters["primary_visits"] += c.visits
        self.counters["primary_tests"] += c.tests
        if self.one_sweep:
            normals = scene.normals_for(hits.prim)
            t0 = time.perf_counter()
            sweep = shade_image(scene.cam, jitter, hits, layout, scene.tri_verts, geom.faces, normals,
                                geom.tri_material, shading.materials, geom.uvs, shading.tex_data, shading.tex_info,
                                shading.lights, scene.shadow_accel.bvh if self.cast_shadows else None,
                                self.first_rows, self.cfg.ambient, self.bg, weight, accumulate, rgba, z)
            dt = (time.perf_counter() - t0) * 1e3
            # the sweep's time split by its threads' cycles spent on shadow rays
            timings["shadow_ms"] += dt * sweep.shadow_share
            timings["shade_ms"] += dt * (1.0 - sweep.shadow_share)
            if self.cast_shadows:
                self.count_shadow_rays(Counters.of(sweep.counters), sweep.shadow_rays, len(self.first_rows),
                                       sweep.samples)
            return
        surface = self.gather(jitter, hits.t, hits.prim, hits.b1, hits.b2, layout, hits.inst)
        rgb = self.shade_surface(surface)
        t0 = time.perf_counter()
        write_pixels(surface.pixel, rgb, surface.depth, self.bg, np.float32(weight), accumulate, rgba, z)
        timings["shade_ms"] += (time.perf_counter() - t0) * 1e3

    def count_camera_rays(self, n, c):
        counters = self.counters
        counters["rays"] += n
        counters["cells"] += c.visits
        counters["tri_tests"] += c.tests
        counters["fallback_rays"] += c.fallback_rays

    def count_shadow_rays(self, c, n_active, n_rows, n_vis):
        counters = self.counters
        counters["shadow_rays"] += n_active
        counters["shadow_rays_skipped"] += n_rows * n_vis - n_active
        counters["tri_tests"] += c.tests
        counters["cells"] += c.visits

    def gather(self, jitter, t, prim, b1, b2, layout, inst=None):
        """The visible surface of one pass of camera hits (timed as shading);
        in an instanced world (inst: the hits' instances) from the seen
        triangles placed in the world (instancing/seen.py), its prim the
        primitives' ids in the flattened world."""
        scene, geom, shading = self.scene, self.geom, self.shading
        t0 = time.perf_counter()
        normals = scene.normals_for(prim)
        tri_verts, faces, tri_material, uvs = scene.tri_verts, geom.faces, geom.tri_material, geom.uvs
        seen = None
        if inst is not None:
            seen = self.buffers.seen_triangles(prim.shape[0], uvs.shape[0] > 0)
            prim, tri_verts, faces, normals, tri_material, uvs = seen.place(
                prim, inst, tri_verts, faces, normals, uvs, tri_material, scene.geom.instances.tri_shift,
                scene.geom.instances.plain, scene.accel.place)
        surface = visible_surface(scene.cam, jitter, t, prim, b1, b2, *layout, tri_verts, faces,
                                  normals, tri_material, shading.materials, uvs, shading.tex_data,
                                  shading.tex_info, self.buffers.work)
        if seen is not None:
            surface.prim[:] = seen.ids[surface.prim]
        self.timings["shade_ms"] += (time.perf_counter() - t0) * 1e3
        return surface

    def trace_shadows(self, surface, vis, rows, coherent, skip=None):
        """vis[li] for the light rows `rows` at the surface's samples: in the
        samples' order by a structure that traces them so (trace_lights,
        the BVH) when they are `coherent`, else a light at a time in
        light-space order (LightRays)."""
        lights, accel, n_vis = self.shading.lights, self.scene.shadow_accel, surface.pixel.shape[0]
        if coherent and hasattr(accel, "trace_lights"):
            self.count_shadow_rays(*accel.trace_lights(surface, lights[rows, :4], rows, vis, skip), len(rows), n_vis)
            return
        for li in rows:
            rays = LightRays(surface, int(lights[li, 0]), lights[li, 1:4], self.buffers.work, skip)
            self.count_shadow_rays(accel.trace_shadows(rays, vis[li]), rays.n_active, 1, n_vis)

    def shade_surface(self, surface, aov=True, coherent=True):
        """Shadow rays and shading of visible samples: rgb (3, n); with aov,
        the samples (one pass's) also offered to the AOVs. coherent: the
        samples are in a camera pass's gather order (32x32-pixel blocks),
        which a structure with trace_lights (the BVH) traces as they come;
        the error budget's scattered samples, and every sample for the
        others, go through LightRays' light-space sort."""
        cfg, shading, buffers = self.cfg, self.shading, self.buffers
        W, H, n_lights = cfg.width, cfg.height, self.n_lights
        t0 = time.perf_counter()
        n_vis = surface.pixel.shape[0]
        vis = buffers.work.take("vis", (n_lights, n_vis if self.cast_shadows else 0), capacity=n_lights * W * H)
        if self.cast_shadows:
            vis[[li for li in range(n_lights) if li not in self.lit]] = 0.0
            # every group's probes (every light that is not an area light's
            # other emitter) at once
            self.trace_shadows(surface, vis, self.first_rows, coherent)
            for rows, probes in self.groups:
                rest = [li for li in rows if li not in probes]
                if not rest:
                    continue
                # every probe lit, or none: the point is out of the penumbra, and
                # the other emitters are taken to agree (no rays); else trace them
                seen = vis[probes].sum(axis=0)
                full, none = seen >= len(probes), seen <= 0
                self.trace_shadows(surface, vis, rest, coherent, full | none)
                for li in rest:
                    vis[li][full] = 1.0
                    vis[li][none] = 0.0
        self.timings["shadow_ms"] += (time.perf_counter() - t0) * 1e3
        t0 = time.perf_counter()
        rgb = buffers.work.take("rgb", (3, n_vis), capacity=3 * W * H)
        on_threads(shade_samples, numba.get_num_threads(), surface.point, surface.smooth_n, surface.view,
                   surface.albedo, surface.ks, surface.shininess, shading.lights, vis, self.cast_shadows,
                   np.float32(cfg.ambient), rgb, new_queue())
        if self.aovs is not None and aov:
            self.aovs.add(surface)
        self.timings["shade_ms"] += (time.perf_counter() - t0) * 1e3
        return rgb

    def refine_pixels(self, rgba, z):
        """The error budget (adaptive.py) over the 1-spp image. A group of passes
        (sample offsets) traces one camera ray per active pixel and offset as
        one ray batch (pixels in adaptive.py's block order, a pixel's rays side
        by side, so that a packet holds neighbours), places each offset's hits
        in an image-sized layout (prim -1 elsewhere) for the surface gather,
        then shadows and shades the group's samples as one set. Tracing instead
        the 4x4 blocks that hold active pixels as camera packets cast 2.4x the
        camera rays and took longer (hand, 256^2, E = 0.02: 171 against 117 ms
        of tracing, pass by pass); shadowing pass by pass took 5x longer (369
        against 76 ms): small scattered sets make loose light-space packets.
        Under motion blur or a thin lens every offset has a time and lens
        position of its own (PassScene), so each is traced and shaded alone.
        Returns the samples per pixel."""
        cfg, scene, buffers, timings, aovs = self.cfg, self.scene, self.buffers, self.timings, self.aovs
        W, H = cfg.width, cfg.height
        n_pix = W * H
        full_t = buffers.work.take("adaptive.t", (n_pix,))
        full_b1 = buffers.work.take("adaptive.b1", (n_pix,))
        full_b2 = buffers.work.take("adaptive.b2", (n_pix,))
        full_prim = buffers.work.take("adaptive.prim", (n_pix,), np.int32)
        full_prim.fill(-1)
        full_inst = buffers.work.take("adaptive.inst", (n_pix,), np.int32) if self.geom.instances is not None \
            else None
        layout = row_major_offsets(W, H)
        centre = plain_times_lens(1)[0]             # the 1-spp image's time and lens (the border ring's too)

        def trace_group(pixels, offsets, aov):
            # every offset's camera rays in one batch, pixel-major (a pixel's rays
            # side by side), so that a packet spans as few pixels as it can
            t0 = time.perf_counter()
            cam, m, g = scene.cam, pixels.shape[0], len(offsets)
            dirs = np.empty((g, m, 3), np.float32)
            for j, (ox, oy) in enumerate(offsets):
                camera_rays_of(cam, pixels, W, np.float32(ox), np.float32(oy), dirs[j])
            hits = scene.accel.trace_rays(np.broadcast_to(np.asarray(cam[:3], np.float32), (m * g, 3)),
                                          np.ascontiguousarray(dirs.transpose(1, 0, 2)).reshape(-1, 3))
            timings["trace_ms"] += (time.perf_counter() - t0) * 1e3
            self.count_camera_rays(m * g, hits.counters)
            surfaces = []
            for j, offset in enumerate(offsets):
                full_t[pixels] = hits.t[j::g]
                full_prim[pixels] = hits.prim[j::g]
                full_b1[pixels] = hits.b1[j::g]
                full_b2[pixels] = hits.b2[j::g]
                if full_inst is not None:
                    full_inst[pixels] = hits.inst[j::g]
                surface = self.gather(offset, full_t, full_prim, full_b1, full_b2, layout, full_inst)
                full_prim[pixels] = -1
                if aovs is not None and aov:
                    aovs.add(surface)
                surfaces.append(Surface(*(np.array(f) for f in surface)))     # out of the workspace
            # the passes' samples shadowed and shaded as one set
            rgb = self.shade_surface(Surface(*(np.concatenate(f, axis=-1) for f in zip(*surfaces))), aov=False,
                                     coherent=False)
            out, k = [], 0
            for s in surfaces:
                n_hit = s.pixel.shape[0]
                # a copy: a slice of the columns is C-contiguous only when it is
                # all of them, and add_pass would compile a second layout mid-render
                out.append((s.pixel, np.ascontiguousarray(rgb[:, k:k + n_hit]), s.depth))
                k += n_hit
            return out

        def sample_of(offset):
            """(time, lens_x, lens_y) of an offset (jx, jy[, time, lens_x, lens_y])."""
            return tuple(offset[2:]) or centre

        def trace_passes(pixels, offsets, aov=True):
            out, i = [], 0
            while i < len(offsets):
                # the run of offsets that share a time and lens position
                sample = sample_of(offsets[i])
                end = i + 1
                while end < len(offsets) and sample_of(offsets[end]) == sample:
                    end += 1
                scene.move_to(sample)
                out += trace_group(pixels, [o[:2] for o in offsets[i:end]], aov)
                i = end
            return out

        moving = scene.motion is not None or cfg.aperture_radius > 0
        samples, _ = refine(rgba, z, W, H, np.asarray(cfg.background, np.float32), cfg.max_error,
                            adaptive_cap(cfg), trace_passes, budget_times_lens(adaptive_cap(cfg)) if moving else None)
        return samples
