"""One frame, phase by phase: build -> trace -> shadow -> shade.

Inputs are flat arrays only (no scene-file objects), so `raycore` never needs
`anim`. Each phase is timed apart; the shadow pass is skipped when there are
no lights or shadows are off, the texture path when nothing is textured, and
the AOV writes when none are asked for.
"""
import time
from typing import NamedTuple

import numpy as np

from .camera import camera_basis
from .config import RenderConfig
from .kdtree_build import build_kdtree
from .kdtree_trace import kd_trace_camera, kd_trace_light
from .scene_grid import SceneGrid
from .shade import shade_pixels
from .trace import Hits, camera_buffers, row_major_offsets, trace_camera, trace_light

# kd-tree camera packets: 8x8 rays per frustum (the grid's packet size is cfg.packet)
KD_PACKET = 8


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


def sample_offsets(spp: int) -> list:
    """Sub-pixel offsets: the pixel centre for spp = 1, else a Hammersley set
    (stratified in x, radical inverse in y): deterministic, low discrepancy."""
    if spp <= 1:
        return [(0.5, 0.5)]
    out = []
    for i in range(spp):
        bits, f, inv = i, 0.0, 0.5
        while bits:
            f += inv * (bits & 1)
            bits >>= 1
            inv *= 0.5
        out.append(((i + 0.5) / spp, f))
    return out


class FrameBuffers:
    """Per-pixel work arrays kept from frame to frame (same resolution): fresh
    large arrays cost page faults on every frame."""

    def __init__(self, width, height, n_lights, packet):
        n = width * height
        self.size = (width, height, n_lights, packet)
        self.camera = camera_buffers(width, height, packet)
        self.vis = np.empty((n_lights, n), np.float32)
        self.rgba = np.empty((n, 4), np.float32)
        self.z = np.empty(n, np.float32)


def render_frame(geom: Geometry, shading: Shading, pose: CameraPose, cfg: RenderConfig,
                 buffers: FrameBuffers = None, scene_grid: SceneGrid = None) -> FrameResult:
    """Render one frame. Pass the same `buffers` and `scene_grid` for
    consecutive frames to reuse work arrays and static geometry; the returned
    images are always fresh arrays."""
    W, H = cfg.width, cfg.height
    n_lights = shading.lights.shape[0]
    if buffers is None or buffers.size != (W, H, n_lights, cfg.packet):
        buffers = FrameBuffers(W, H, n_lights, cfg.packet)
    timings = {"build_ms": 0.0, "trace_ms": 0.0, "shadow_ms": 0.0, "shade_ms": 0.0}
    counters = {"rays": 0, "shadow_rays": 0, "tri_tests": 0, "cells": 0, "fallback_rays": 0,
                "primary_packets": 0, "primary_visits": 0, "primary_tests": 0}
    if scene_grid is None:
        scene_grid = SceneGrid(geom.faces, len(geom.vertices), geom.vf_start, geom.vf_faces, cfg.grid_density)
    kd = cfg.accel == "kdtree"
    t0 = time.perf_counter()
    if kd:
        tri_verts = scene_grid.gather(geom.vertices)
        tree = scene_grid.kd_tree
        if tree is None:
            tree = build_kdtree(tri_verts)
            if scene_grid.all_static:           # a fly-through: build the tree once
                scene_grid.kd_tree = tree
        counters["kd_nodes"] = int(len(tree.axis))
    else:
        grid, tri_verts = scene_grid.update(geom.vertices)
        counters["grid_dims"] = [int(d) for d in grid.dims]
    timings["build_ms"] = (time.perf_counter() - t0) * 1e3

    t0 = time.perf_counter()
    normals = scene_grid.normals_now()
    timings["shade_ms"] += (time.perf_counter() - t0) * 1e3

    cam = camera_basis(pose.eye, pose.look_at, pose.up, pose.fov, W, H)
    bg = np.asarray(cfg.background, np.float32)
    cast_shadows = cfg.shadows and n_lights > 0 and geom.faces.shape[0] > 0
    want_aov = any(a in cfg.aovs for a in ("N", "P"))
    offsets = sample_offsets(cfg.spp)
    single = len(offsets) == 1
    # the frame's images are fresh arrays (they go to the writer thread); with
    # one sample the shader writes them directly, else samples are averaged
    acc_rgba = np.empty((H * W, 4), np.float32) if single else np.zeros((H * W, 4), np.float32)
    z = np.empty(H * W, np.float32) if single else np.full(H * W, np.inf, np.float32)
    rgba = acc_rgba if single else buffers.rgba
    z_s = z if single else buffers.z
    aov_n = np.empty((H * W if want_aov else 0, 3), np.float32)
    aov_p = np.empty_like(aov_n)
    first_prim = None
    for jitter in offsets:
        t0 = time.perf_counter()
        if kd:
            hits = Hits(*kd_trace_camera(tree, tri_verts, cam, W, H, KD_PACKET, jitter))
            layout = row_major_offsets(W, H)
        else:
            hits = trace_camera(grid, tri_verts, cam, W, H, cfg.packet, jitter, buffers.camera,
                                row_major=False, cull=cfg.grid_cull)
            layout = (buffers.camera.row_off, buffers.camera.col_off)
        timings["trace_ms"] += (time.perf_counter() - t0) * 1e3
        counters["rays"] += W * H
        counters["cells"] += int(hits.counters[1])
        counters["tri_tests"] += int(hits.counters[2])
        counters["fallback_rays"] += int(hits.counters[4])
        # primary rays alone (grid: cells; kd-tree: nodes), for `frustrace compare`
        counters["primary_packets"] += int(hits.counters[0])
        counters["primary_visits"] += int(hits.counters[1])
        counters["primary_tests"] += int(hits.counters[2])

        t0 = time.perf_counter()
        vis = buffers.vis if cast_shadows else buffers.vis[:0]
        if cast_shadows:
            visible = int(np.count_nonzero(hits.prim >= 0))   # padding slots are -1
            for li in range(n_lights):
                kind = int(shading.lights[li, 0])
                if kd:
                    _, c = kd_trace_light(tree, tri_verts, cam, W, H, hits, kind, shading.lights[li, 1:4],
                                          jitter, vis[li], layout, (geom.faces, normals))
                else:
                    _, c = trace_light(grid, tri_verts, cam, W, H, hits, kind,
                                       shading.lights[li, 1:4], cfg.packet, jitter, vis[li], layout,
                                       (geom.faces, normals), cfg.grid_cull)
                counters["shadow_rays"] += visible
                counters["tri_tests"] += int(c[2])
                counters["cells"] += int(c[1])
        timings["shadow_ms"] += (time.perf_counter() - t0) * 1e3

        t0 = time.perf_counter()
        shade_pixels(cam, W, H, np.float32(jitter[0]), np.float32(jitter[1]),
                     hits.t, hits.prim, hits.b1, hits.b2, *layout, tri_verts, geom.faces, normals,
                     geom.tri_material, shading.materials, geom.uvs, shading.tex_data,
                     shading.tex_info, shading.lights, vis, cast_shadows, bg,
                     np.float32(cfg.ambient), rgba, z_s, want_aov and jitter == offsets[0],
                     aov_n, aov_p)
        if not single:
            acc_rgba += rgba
            np.minimum(z, z_s, out=z)
        if first_prim is None and "id" in cfg.aovs:      # gathered to row-major here
            first_prim = hits.prim[layout[0][:, None] + layout[1][None, :]].reshape(-1)
        timings["shade_ms"] += (time.perf_counter() - t0) * 1e3
    if not single:
        acc_rgba /= len(offsets)
    aovs = {}
    if "N" in cfg.aovs:
        for i, c in enumerate("XYZ"):
            aovs[f"N.{c}"] = aov_n[:, i].reshape(H, W)
    if "P" in cfg.aovs:
        for i, c in enumerate("XYZ"):
            aovs[f"P.{c}"] = aov_p[:, i].reshape(H, W)
    if "id" in cfg.aovs:
        aovs["id"] = first_prim.astype(np.float32).reshape(H, W)
    return FrameResult(acc_rgba.reshape(H, W, 4), z.reshape(H, W), aovs, timings, counters)
