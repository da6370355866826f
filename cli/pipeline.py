"""The render loop: anim (vertices at t) -> raycore (frame) -> EXR, per frame.

Writing a frame goes through a writer thread, but the render of the next frame
waits for it (MAX_PENDING_WRITES = 0): on this 2-core machine kind the
OpenImageIO write (150-250 ms per 1024^2 frame) holds a core, and numba's
statically split parallel regions then stall on it, slowing the render phases
by 2-50x, which costs more than the overlap gains. Raise the constant on
machines with cores to spare. Compile time is measured apart by a small
warm-up render and never mixed into fps.
"""
import json
import re
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

import numpy as np

from anim.errors import SceneError
from anim.scene import AnimatedScene
from raycore.config import RenderConfig
from raycore.frame import CameraPose, FrameBuffers, Geometry, Shading, render_frame
from raycore.image_io import read_texture, write_exr
from raycore.mesh import vertex_face_csr
from raycore.scene_grid import SceneGrid

VERSION = "0.1.0"
MAX_PENDING_WRITES = 0


def frame_path(pattern: str, frame: int) -> str:
    """Replace the run of '#' (the schema allows one) with the frame number,
    zero-padded to the run's width; a negative frame gets its sign in front
    of the padded digits (frame -1 in f_###.exr: f_-001.exr)."""
    runs = re.findall(r"#+", pattern)
    if not runs:
        return pattern
    width = len(runs[-1])
    head, _, tail = pattern.rpartition(runs[-1])
    return f"{head}{'-' if frame < 0 else ''}{abs(frame):0{width}d}{tail}"


def config_of(scene: AnimatedScene, **overrides) -> RenderConfig:
    """The scene file's render settings, with command-line overrides."""
    spec = scene.spec
    base = dict(width=spec.output.resolution[0], height=spec.output.resolution[1],
                packet=spec.render.packet, spp=spec.render.spp, shadows=spec.render.shadows,
                accel=spec.render.accel, grid_density=spec.render.grid_density,
                background=tuple(spec.render.background), ambient=spec.render.ambient,
                aovs=tuple(spec.output.aovs))
    base.update({k: v for k, v in overrides.items() if v is not None})
    return RenderConfig(**base)


def shading_of(scene: AnimatedScene) -> Shading:
    """Materials, lights and textures as flat arrays; textures loaded once."""
    texels, info, offset = [], [], 0
    for path, space, key in zip(scene.texture_paths, scene.texture_spaces, scene.texture_keys):
        try:
            img = read_texture(path, space)
        except OSError as exc:
            raise SceneError(scene.path, key, f"cannot read texture: {exc}") from None
        h, w = img.shape[:2]
        texels.append(img.reshape(-1))
        info.append((offset, w, h))
        offset += img.size
    tex_data = np.concatenate(texels) if texels else np.zeros(1, np.float32)
    tex_info = np.asarray(info, np.int64).reshape(-1, 3)
    return Shading(scene.material_table, tex_data, tex_info, scene.light_table)


class RenderJob(NamedTuple):
    scene: AnimatedScene
    cfg: RenderConfig
    frames: list
    out_dir: Path
    stats_path: Path
    resume: bool
    overwrite: bool


def plan_frames(scene, out_dir, frames, resume, overwrite):
    """(frame, path) pairs to render. Finished frames are skipped with --resume;
    without --resume or --overwrite an existing frame is an error."""
    todo = []
    pattern = scene.spec.output.path
    if "#" not in pattern and len(frames) > 1:
        raise SceneError(scene.path, "output.path", "needs a run of '#' for the frame number when rendering several frames")
    for f in frames:
        path = Path(frame_path(pattern, f))
        if out_dir is not None:
            path = out_dir / path.name
        elif not path.is_absolute():
            path = scene.path.parent / path
        if path.exists() and not overwrite:
            if resume:
                continue
            raise SceneError(path, "", "frame exists; use --resume to skip finished frames or --overwrite to replace them")
        todo.append((f, path))
    return todo


class SceneRenderer:
    """Frames of one scene, rendered with reused work buffers: interpolate
    (timed as interp_ms), then build, trace, shadow and shade."""

    def __init__(self, scene: AnimatedScene, cfg: RenderConfig, shading: Shading):
        self.scene, self.cfg, self.shading = scene, cfg, shading
        self.vf = vertex_face_csr(scene.faces, scene.n_vertices)
        # image ring: the frame being written, the one being rendered, and every write in flight
        self.buffers = FrameBuffers(cfg.width, cfg.height, shading.lights.shape[0], cfg.packet,
                                    n_images=MAX_PENDING_WRITES + 2)
        # static objects: gathered, binned and given normals once (raycore/scene_grid.py)
        self.scene_grid = SceneGrid(scene.faces, scene.n_vertices, *self.vf, cfg.grid_density,
                                    scene.moving_triangles)

    def render(self, t):
        """(interp_ms, FrameResult) of the frame at time t."""
        scene = self.scene
        t0 = time.perf_counter()
        vertices = scene.vertices_at(t)
        pose = CameraPose(*scene.camera_at(t))
        interp_ms = (time.perf_counter() - t0) * 1e3
        geom = Geometry(vertices, scene.faces, scene.tri_material, scene.uvs, *self.vf)
        return interp_ms, render_frame(geom, self.shading, pose, self.cfg, self.buffers, self.scene_grid)


def warm_up(scene, shading, cfg, t) -> float:
    """Compile (or load from numba's cache) every kernel on a tiny image: seconds."""
    t0 = time.perf_counter()
    small = cfg.__class__(**{**cfg.__dict__, "width": 2 * cfg.packet, "height": 2 * cfg.packet, "spp": 1})
    SceneRenderer(scene, small, shading).render(t)
    return time.perf_counter() - t0


def render_animation(job: RenderJob, on_frame=None) -> dict:
    scene, cfg = job.scene, job.cfg
    shading = shading_of(scene)
    todo = plan_frames(scene, job.out_dir, job.frames, job.resume, job.overwrite)
    for _, path in todo:
        path.parent.mkdir(parents=True, exist_ok=True)
    first_t = scene.time_of(todo[0][0] if todo else scene.frame_numbers[0])
    compile_s = warm_up(scene, shading, cfg, first_t)
    renderer = SceneRenderer(scene, cfg, shading)
    rows = []

    def write(path, result, row):
        t0 = time.perf_counter()
        channels = {"RGBA": result.rgba, "Z": result.z, **result.aovs}
        meta = {"frustrace:frame": int(row["frame"]), "frustrace:time": float(row["time"]),
                "Software": f"frustrace {VERSION}"}
        for k in ("interp_ms", "build_ms", "trace_ms", "shade_ms", "shadow_ms"):
            meta[f"frustrace:{k}"] = float(row[k])
        write_exr(str(path), channels, meta, scene.spec.output.compression)
        row["write_ms"] = (time.perf_counter() - t0) * 1e3   # read only after the write ends

    wall0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=1) as writer:
        pending = []
        for frame, path in todo:
            while len(pending) > MAX_PENDING_WRITES:
                pending.pop(0).result()
            t = scene.time_of(frame)
            # a frame's images come from a ring of MAX_PENDING_WRITES + 2 sets, and
            # at most MAX_PENDING_WRITES writes are unfinished while it renders, so the
            # writer thread never sees its images overwritten
            interp_ms, result = renderer.render(t)
            tm = result.timings
            rays = result.counters["rays"]
            row = {"frame": frame, "time": t, "triangles": int(scene.faces.shape[0]), "rays": rays,
                   "interp_ms": interp_ms, **tm, "write_ms": 0.0,
                   "tri_tests": float(result.counters["tri_tests"]),
                   "shadow_rays": result.counters["shadow_rays"],
                   "cells_visited": result.counters["cells"],   # kd-tree: nodes visited
                   "fallback_rays": result.counters["fallback_rays"],
                   **({"grid_dims": result.counters["grid_dims"]} if "grid_dims" in result.counters
                      else {"kd_nodes": result.counters["kd_nodes"]}),
                   "mrays_per_s": rays / max(tm["trace_ms"], 1e-9) / 1e3}
            rows.append(row)
            pending.append(writer.submit(write, path, result, row))
            if on_frame:
                on_frame(row)
        for p in pending:
            p.result()
    wall_s = time.perf_counter() - wall0
    stats = {"scene": scene.path.name, "resolution": [cfg.width, cfg.height], "accel": cfg.accel,
             "packet": cfg.packet, "threads": cfg.threads, "frames": rows,
             "summary": summarize(rows, wall_s, compile_s)}
    job.stats_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = job.stats_path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(stats, indent=1))
    tmp.replace(job.stats_path)
    return stats


def median_ms(rows, *keys) -> float:
    """Median over frames of the sum of the given phase timings (0 if none)."""
    return float(np.median([sum(r[k] for k in keys) for r in rows])) if rows else 0.0


def fps_of(rows):
    """(fps_raycast, fps_full) as SPEC section 5 defines them."""
    raycast = median_ms(rows, "interp_ms", "build_ms", "trace_ms")
    full = median_ms(rows, "interp_ms", "build_ms", "trace_ms", "shade_ms", "shadow_ms")
    return (1000.0 / raycast if raycast > 0 else 0.0), (1000.0 / full if full > 0 else 0.0)


def summarize(rows, wall_s, compile_s) -> dict:
    """The stats.json summary: fps (medians over frames), compile time apart."""
    fps_raycast, fps_full = fps_of(rows)
    return {"fps_raycast": fps_raycast, "fps_full": fps_full,
            "fps_wall": len(rows) / wall_s if rows and wall_s > 0 else 0.0,
            "compile_s": compile_s,
            "median_ms": {k: median_ms(rows, k) for k in ("interp_ms", "build_ms", "trace_ms",
                                                         "shade_ms", "shadow_ms", "write_ms")}}
