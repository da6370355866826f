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

from .accelerators import KD_PACKET, BvhAccel, GridAccel, KdAccel
from .adaptive import camera_rays_of, refine
from .camera import camera_basis, thin_lens
from .config import ADAPTIVE_SPP_CAP, SHADOW_ACCEL, RenderConfig
from .counters import Counters
from .kdtree_build import build_kdtree
from .sampling import sample_offsets
from .scene_grid import SceneGrid
from .shade import shade_samples, write_pixels
from .shade_blocks import shade_image
from .shadow_rays import LightRays
from .shutter_lens import budget_times_lens, plain_times_lens
from .surface import Surface, visible_surface
from .thread_pool import on_threads
from .tile_queue import new_queue
from .trace import camera_buffers, row_major_offsets
from .workspace import Workspace

# False: every pass takes the phase by phase path (to measure the sweep against it)
ONE_SWEEP = True

__all__ = ["KD_PACKET", "CameraPose", "FrameBuffers", "FrameResult", "Geometry", "Shading", "render_frame"]


class Geometry(NamedTuple):
    """Triangles of one frame (all objects concatenated)."""
    vertices: np.ndarray      # (n_v, 3) f32, this frame's positions
    faces: np.ndarray         # (n_t, 3) i32
    tri_material: np.ndarray  # (n_t,) i32 index into Shading.materials
    uvs: np.ndarray           # (n_v, 2) f32, or (0, 2) when untextured
    vf_start: np.ndarray      # vertex -> faces CSR (see mesh.vertex_face_csr)
    vf_faces: np.ndarray


class Shading(NamedTuple):
    materials: np.ndarray     # (n_mat, 8) f32, see shade.py
    tex_data: np.ndarray      # f32 texels
    tex_info: np.ndarray      # (n_tex, 3) i64
    lights: np.ndarray        # (n_light, 8) f32, see shade.py


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


def _light_is_dark(light) -> bool:
    """A light of zero colour * intensity adds nothing: it costs no ray."""
    return not np.any(light[4:7] > 0)


class PassScene:
    """The structures, vertex normals and camera that a pass traces: built
    once for a frame without motion blur, moved to each pass's time under
    it (rebuilt only when the vertices changed: a frame in which only the
    camera moves, or nothing within the shutter, builds once), and the
    camera put at each pass's lens position under a thin lens."""

    def __init__(self, names, geom, pose, cfg, scene_grid, buffers, counters, timings, motion,
                 camera_accel, shadow_accel):
        self.names, self.geom, self.cfg, self.scene_grid = names, geom, cfg, scene_grid
        self.buffers, self.counters, self.timings, self.motion = buffers, counters, timings, motion
        self.camera_accel, self.fixed_shadow_accel = camera_accel, shadow_accel
        self.key = None                      # (time, lens) of what is built now
        self.built_vertices = None           # the vertices the structures were built over
        self.pose = self.pinhole = None
        self.times_seen, self.lens_seen = set(), set()
        if motion is None:                   # else the first pass's move_to builds
            self.build(geom.vertices, pose)

    def build(self, vertices, pose):
        cfg, t0 = self.cfg, time.perf_counter()
        if self.built_vertices is None or not np.array_equal(vertices, self.built_vertices):
            geom = self.geom._replace(vertices=vertices)
            self.tri_verts, built = build_structures(self.names, geom, self.cfg, self.scene_grid, self.buffers,
                                                     self.counters)
            self.accel = built[cfg.accel] if self.camera_accel is None else self.camera_accel
            self.shadow_accel = (built.get(cfg.shadow_accel or SHADOW_ACCEL) if self.fixed_shadow_accel is None
                                 else self.fixed_shadow_accel)
            self.built_vertices = vertices.copy() if self.motion is not None else vertices
            self.counters["builds"] += 1
            self.timings["build_ms"] += (time.perf_counter() - t0) * 1e3
            t0 = time.perf_counter()
            self.normals = self.scene_grid.normals_now()
            self.timings["shade_ms"] += (time.perf_counter() - t0) * 1e3
        if pose != self.pose:
            self.pose = pose
            self.pinhole = camera_basis(pose.eye, pose.look_at, pose.up, pose.fov, cfg.width, cfg.height)
        self.cam = self.pinhole

    def move_to(self, sample):
        """Structures and camera of a pass at (time, lens_x, lens_y): time in
        [0, 1] across the shutter (motion(time) gives the vertices and the
        camera pose), lens on the unit disc."""
        if sample == self.key:
            return
        self.key = sample
        u, lx, ly = sample
        self.counters["passes"] += 1
        self.times_seen.add(u)
        self.lens_seen.add((lx, ly))
        if self.motion is not None:
            self.build(*self.motion(u))
        self.cam = self.pinhole
        if self.cfg.aperture_radius > 0 and (lx != 0.0 or ly != 0.0):
            self.cam = thin_lens(self.pinhole, lx, ly, self.cfg.aperture_radius, focus_of(self.pose, self.cfg))


def focus_of(pose, cfg) -> float:
    """The focus distance along the view axis: the scene's, or the eye's
    distance to the point it looks at."""
    if cfg.focus_distance > 0:
        return cfg.focus_distance
    return float(np.linalg.norm(np.subtract(pose.look_at, pose.eye, dtype=np.float64)))


def render_frame(geom: Geometry, shading: Shading, pose: CameraPose, cfg: RenderConfig,
                 buffers: FrameBuffers = None, scene_grid: SceneGrid = None,
                 camera_accel=None, shadow_accel=None, motion=None) -> FrameResult:
    """Render one frame. Pass the same `buffers` and `scene_grid` for
    consecutive frames to reuse work arrays, image memory and static geometry;
    the returned images then belong to the buffers' ring (see FrameBuffers),
    else they are fresh arrays.

    Per pass of camera rays (one per sample offset): trace, gather the visible
    surface once (surface.py), trace each light's shadow rays in light-space
    packets (shadow_rays.py) through cfg.shadow_accel, shade the samples,
    scatter them into the image.

    motion: under motion blur, u -> (vertices, CameraPose) at shutter
    position u in [0, 1] (geom and pose are those of the frame's own time);
    each pass then takes its own time (shutter_lens.py). None: nothing moves
    within the frame.

    camera_accel, shadow_accel: objects with the accelerators' methods used
    for the camera or shadow rays instead of building cfg.accel or the
    shadow structure (the compile helper's stand-ins,
    anim/render/compile_helper.py)."""
    W, H = cfg.width, cfg.height
    n_lights = shading.lights.shape[0]
    if buffers is None or buffers.size != (W, H, n_lights, cfg.packet):
        buffers = FrameBuffers(W, H, n_lights, cfg.packet, n_images=1)
    timings = {"build_ms": 0.0, "trace_ms": 0.0, "shadow_ms": 0.0, "shade_ms": 0.0}
    counters = {"rays": 0, "shadow_rays": 0, "shadow_rays_skipped": 0, "lights_skipped": 0,
                "tri_tests": 0, "cells": 0, "fallback_rays": 0,
                "primary_packets": 0, "primary_visits": 0, "primary_tests": 0, "builds": 0, "passes": 0}
    if scene_grid is None:
        scene_grid = SceneGrid(geom.faces, len(geom.vertices), geom.vf_start, geom.vf_faces, cfg.grid_density)
    lit = [li for li in range(n_lights) if not _light_is_dark(shading.lights[li])]
    counters["lights_skipped"] = n_lights - len(lit)
    cast_shadows = cfg.shadows and len(lit) > 0 and geom.faces.shape[0] > 0
    # the structures are chosen here, once: everything below goes through
    # their common surface (accelerators.py)
    shadow_name = cfg.shadow_accel or SHADOW_ACCEL
    names = (({shadow_name} if cast_shadows and shadow_accel is None else set())
             | ({cfg.accel} if camera_accel is None else set()))
    scene = PassScene(names, geom, pose, cfg, scene_grid, buffers, counters, timings, motion,
                      camera_accel, shadow_accel)

    bg = np.asarray(cfg.background, np.float32)
    # under an error budget the image starts from the pixel centres, and spp
    # is the most samples a pixel may get (adaptive.py)
    offsets = sample_offsets(1 if cfg.max_error > 0 else cfg.spp)
    times_lens = plain_times_lens(len(offsets))
    single = len(offsets) == 1
    # one sample: the pass writes the image; several: each adds 1/spp of its own
    rgba, z = buffers.image()
    if not single:
        rgba.fill(0.0)
        z.fill(np.inf)
    aovs = NearestAOVs(cfg.aovs, W * H) if cfg.aovs else None

    def count_camera_rays(n, c):
        counters["rays"] += n
        counters["cells"] += c.visits
        counters["tri_tests"] += c.tests
        counters["fallback_rays"] += c.fallback_rays

    def count_shadow_rays(c, n_active, n_rows, n_vis):
        counters["shadow_rays"] += n_active
        counters["shadow_rays_skipped"] += n_rows * n_vis - n_active
        counters["tri_tests"] += c.tests
        counters["cells"] += c.visits

    # the lights in groups (an area light's emitters together) and the rows
    # traced for every sample first (each group's probes)
    groups = ([(rows, probe_rows(rows, cfg.light_probes)) for rows in light_groups(shading.lights, lit)]
              if cast_shadows else [])
    first_rows = [li for _, probes in groups for li in probes]

    def one_sweep():
        """Whether this pass's hits can go to pixels in one sweep
        (shade_blocks.py): no AOVs, and no shadows or BVH shadows whose
        every ray is traced for every sample (no area light's emitters
        waiting for its probes)."""
        return ONE_SWEEP and aovs is None and (not cast_shadows or (isinstance(scene.shadow_accel, BvhAccel)
                                                       and all(len(r) == len(p) for r, p in groups)))

    def shade_surface(surface, aov=True, coherent=True):
        """Shadow rays and shading of visible samples: rgb (3, n); with aov,
        the samples (one pass's) also offered to the AOVs. coherent: the
        samples are in a camera pass's gather order (32x32-pixel blocks),
        which a structure with trace_lights (the BVH) traces as they come;
        the error budget's scattered samples, and every sample for the
        others, go through LightRays' light-space sort."""
        t0 = time.perf_counter()
        n_vis = surface.pixel.shape[0]
        vis = buffers.work.take("vis", (n_lights, n_vis if cast_shadows else 0), capacity=n_lights * W * H)
        if cast_shadows:
            vis[[li for li in range(n_lights) if li not in lit]] = 0.0
            direct = coherent and hasattr(scene.shadow_accel, "trace_lights")

            def trace(rows, skip=None):
                if direct:
                    count_shadow_rays(*scene.shadow_accel.trace_lights(surface, shading.lights[rows, :4], rows,
                                                                       vis, skip), len(rows), n_vis)
                    return
                for li in rows:
                    rays = LightRays(surface, int(shading.lights[li, 0]), shading.lights[li, 1:4], buffers.work,
                                     skip)
                    count_shadow_rays(scene.shadow_accel.trace_shadows(rays, vis[li]), rays.n_active, 1, n_vis)
            # every group's probes (every light that is not an area light's
            # other emitter) at once
            trace(first_rows)
            for rows, probes in groups:
                rest = [li for li in rows if li not in probes]
                if not rest:
                    continue
                # every probe lit, or none: the point is out of the penumbra, and
                # the other emitters are taken to agree (no rays); else trace them
                seen = vis[probes].sum(axis=0)
                full, none = seen >= len(probes), seen <= 0
                trace(rest, full | none)
                for li in rest:
                    vis[li][full] = 1.0
                    vis[li][none] = 0.0
        timings["shadow_ms"] += (time.perf_counter() - t0) * 1e3
        t0 = time.perf_counter()
        rgb = buffers.work.take("rgb", (3, n_vis), capacity=3 * W * H)
        on_threads(shade_samples, numba.get_num_threads(), surface.point, surface.smooth_n, surface.view,
                   surface.albedo, surface.ks, surface.shininess, shading.lights, vis, cast_shadows,
                   np.float32(cfg.ambient), rgb, new_queue())
        if aovs is not None and aov:
            aovs.add(surface)
        timings["shade_ms"] += (time.perf_counter() - t0) * 1e3
        return rgb

    def gather(jitter, t, prim, b1, b2, layout):
        """The visible surface of one pass of camera hits (timed as shading)."""
        t0 = time.perf_counter()
        surface = visible_surface(scene.cam, jitter, t, prim, b1, b2, *layout, scene.tri_verts, geom.faces,
                                  scene.normals, geom.tri_material, shading.materials, geom.uvs, shading.tex_data,
                                  shading.tex_info, buffers.work)
        timings["shade_ms"] += (time.perf_counter() - t0) * 1e3
        return surface

    for jitter, sample in zip(offsets, times_lens):
        scene.move_to(sample)
        t0 = time.perf_counter()
        hits, layout = scene.accel.trace_camera(scene.cam, W, H, jitter)
        timings["trace_ms"] += (time.perf_counter() - t0) * 1e3
        c = hits.counters
        count_camera_rays(W * H, c)
        # primary rays alone (grid: cells; kd-tree: nodes), for `frustrace compare`
        counters["primary_packets"] += c.packets
        counters["primary_visits"] += c.visits
        counters["primary_tests"] += c.tests
        if one_sweep():
            t0 = time.perf_counter()
            sweep = shade_image(scene.cam, jitter, hits, layout, scene.tri_verts, geom.faces, scene.normals,
                                geom.tri_material, shading.materials, geom.uvs, shading.tex_data, shading.tex_info,
                                shading.lights, scene.shadow_accel.bvh if cast_shadows else None, first_rows,
                                cfg.ambient, bg, 1.0 / len(offsets), not single, rgba, z)
            dt = (time.perf_counter() - t0) * 1e3
            # the sweep's time split by its threads' cycles spent on shadow rays
            timings["shadow_ms"] += dt * sweep.shadow_share
            timings["shade_ms"] += dt * (1.0 - sweep.shadow_share)
            if cast_shadows:
                count_shadow_rays(Counters.of(sweep.counters), sweep.shadow_rays, len(first_rows), sweep.samples)
            continue
        surface = gather(jitter, hits.t, hits.prim, hits.b1, hits.b2, layout)
        rgb = shade_surface(surface)
        t0 = time.perf_counter()
        write_pixels(surface.pixel, rgb, surface.depth, bg, np.float32(1.0 / len(offsets)),
                     not single, rgba, z)
        timings["shade_ms"] += (time.perf_counter() - t0) * 1e3

    samples = None
    if cfg.max_error > 0 and single:
        samples = refine_pixels(rgba, z, cfg, scene, buffers, gather, shade_surface, count_camera_rays,
                                timings, aovs)
        counters["adaptive_spp_mean"] = float(samples.mean())
        counters["spp_cap"] = adaptive_cap(cfg)
        counters["rays_left_out"] = adaptive_cap(cfg) * W * H - counters["rays"]
    if motion is not None or cfg.aperture_radius > 0:
        counters["time_samples"] = len(scene.times_seen) if motion is not None else 1
        counters["lens_samples"] = len(scene.lens_seen) if cfg.aperture_radius > 0 else 1
    return FrameResult(rgba.reshape(H, W, 4), z.reshape(H, W), aovs.channels(H, W) if aovs else {},
                       timings, counters, samples)


def build_structures(names, geom, cfg, scene_grid, buffers, counters):
    """(tri_verts, {name: accelerator}) for this frame's vertices: the
    triangles gathered once, then each named structure built (grid, kd-tree)
    or updated (the BVH's refit trees, scene_bvh.py) over them."""
    built = {}
    if "grid" in names:
        grid, tri_verts = scene_grid.update(geom.vertices)
        counters["grid_dims"] = [int(d) for d in grid.dims]
        built["grid"] = GridAccel(grid, tri_verts, cfg.packet, cfg.grid_cull, buffers.camera)
    else:
        tri_verts = scene_grid.gather(geom.vertices)
    if "kdtree" in names:
        tree = scene_grid.kd_tree
        if tree is None:
            tree = build_kdtree(tri_verts)
            if scene_grid.all_static:           # a fly-through: build the tree once
                scene_grid.kd_tree = tree
        counters["kd_nodes"] = int(len(tree.axis))
        built["kdtree"] = KdAccel(tree, tri_verts)
    if "bvh" in names:
        trees = scene_grid.scene_bvh()
        built["bvh"] = BvhAccel(trees.update(tri_verts, geom.vertices), tri_verts, buffers.work)
        counters.update(trees.stats)
    return tri_verts, built


def adaptive_cap(cfg: RenderConfig) -> int:
    """The most samples a pixel gets under an error budget: spp, or
    ADAPTIVE_SPP_CAP when spp is 1."""
    return cfg.spp if cfg.spp > 1 else ADAPTIVE_SPP_CAP


def refine_pixels(rgba, z, cfg, scene, buffers, gather, shade_surface, count_camera_rays, timings, aovs):
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
    W, H = cfg.width, cfg.height
    n_pix = W * H
    full_t = buffers.work.take("adaptive.t", (n_pix,))
    full_b1 = buffers.work.take("adaptive.b1", (n_pix,))
    full_b2 = buffers.work.take("adaptive.b2", (n_pix,))
    full_prim = buffers.work.take("adaptive.prim", (n_pix,), np.int32)
    full_prim.fill(-1)
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
        count_camera_rays(m * g, hits.counters)
        surfaces = []
        for j, offset in enumerate(offsets):
            full_t[pixels] = hits.t[j::g]
            full_prim[pixels] = hits.prim[j::g]
            full_b1[pixels] = hits.b1[j::g]
            full_b2[pixels] = hits.b2[j::g]
            surface = gather(offset, full_t, full_prim, full_b1, full_b2, layout)
            full_prim[pixels] = -1
            if aovs is not None and aov:
                aovs.add(surface)
            surfaces.append(Surface(*(np.array(f) for f in surface)))     # out of the workspace
        # the passes' samples shadowed and shaded as one set
        rgb = shade_surface(Surface(*(np.concatenate(f, axis=-1) for f in zip(*surfaces))), aov=False,
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


class NearestAOVs:
    """N, P and id of each pixel's nearest hit among its samples: the sample
    whose depth Z reports, so that the AOVs agree with Z (and with A > 0)
    at partly covered edge pixels. 0, 0 and -1 where no sample hit. Only the
    AOVs asked for are kept."""

    def __init__(self, names, n_pix):
        self.names = names
        self.depth = np.full(n_pix, np.inf, np.float32)
        self.n = np.zeros((n_pix, 3), np.float32) if "N" in names else None
        self.p = np.zeros((n_pix, 3), np.float32) if "P" in names else None
        self.prim = np.full(n_pix, -1.0, np.float32) if "id" in names else None

    def add(self, surface):
        """Take this pass's samples that are nearer than what each pixel has."""
        nearer = surface.depth < self.depth[surface.pixel]
        pix = surface.pixel[nearer]
        self.depth[pix] = surface.depth[nearer]
        if self.n is not None:
            self.n[pix] = surface.smooth_n[:, nearer].T
        if self.p is not None:
            self.p[pix] = surface.point[:, nearer].T
        if self.prim is not None:
            self.prim[pix] = surface.prim[nearer]

    def channels(self, height, width):
        out = {}
        for name, values in (("N", self.n), ("P", self.p)):
            if values is not None:
                for i, c in enumerate("XYZ"):
                    out[f"{name}.{c}"] = values[:, i].reshape(height, width)
        if self.prim is not None:
            out["id"] = self.prim.reshape(height, width)
        return out
