"""The render loop: anim (vertices at t) -> raycore (frame) -> EXR, per frame.

Writing a frame goes through a writer thread, but the render of the next frame
waits for it (MAX_PENDING_WRITES = 0): on this 2-core machine kind the
OpenImageIO write (150-250 ms per 1024^2 frame) holds a core, and numba's
statically split parallel regions then stall on it, slowing the render phases
by 2-50x, which costs more than the overlap gains. Raise the constant on
machines with cores to spare. Compile time is measured apart by a small
warm-up render and never mixed into fps.
"""
import fcntl
import json
import os
import re
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

import numpy as np

from anim.errors import SceneError
from anim.scene import AnimatedScene
from raycore.config import RenderConfig
from raycore.frame import KD_PACKET, CameraPose, FrameBuffers, Geometry, Shading, render_frame
from raycore.image_io import read_texture, write_exr
from raycore.mesh import vertex_face_csr
from raycore.scene_grid import SceneGrid

from .output_dir import claim, release, remove_stale_temps, whole_frame
from .paths import writable_dir, writable_file

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
                light_probes=spec.render.light_probes,
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


def frame_channels(cfg: RenderConfig) -> list:
    """The EXR channels a frame of this render has (SPEC section 4)."""
    extra = {"N": ["N.X", "N.Y", "N.Z"], "P": ["P.X", "P.Y", "P.Z"], "id": ["id"]}
    return ["R", "G", "B", "A", "Z"] + [c for a in cfg.aovs for c in extra[a]]


def frame_file(scene, out_dir, frame) -> Path:
    """Where frame `frame` goes: output.path's name in out_dir, or
    output.path itself, relative to the scene file."""
    path = Path(frame_path(scene.spec.output.path, frame))
    if out_dir is not None:
        return out_dir / path.name
    return path if path.is_absolute() else scene.path.parent / path


def plan_frames(scene, out_dir, frames, resume, overwrite, cfg=None, warn=None):
    """(frame, path) pairs to render. With --resume, a frame is skipped only
    if its file is a whole frame of this render (cfg's size and channels):
    a truncated or foreign file is rendered again, said through `warn`.
    Without --resume or --overwrite an existing frame is an error."""
    todo = []
    pattern = scene.spec.output.path
    if "#" not in pattern and len(frames) > 1:
        raise SceneError(scene.path, "output.path", "needs a run of '#' for the frame number when rendering several frames")
    for f in frames:
        path = frame_file(scene, out_dir, f)
        if path.exists() and not overwrite:
            if not resume:
                raise SceneError(path, "", "frame exists; use --resume to skip finished frames or --overwrite to replace them")
            problem = whole_frame(path, cfg.width, cfg.height, frame_channels(cfg)) if cfg else ""
            if not problem:
                continue
            if warn:
                warn(f"{path}: {problem}; rendering frame {f} again")
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


# bytes per pixel of one pass: camera hits (16), the visible-surface rows (96),
# one light's shadow rays and their sort (52), shaded colour (12), the image
# ring (2 x 20), the half-float copy and the EXR codec's buffers (~28)
BYTES_PER_PIXEL = 16 + 96 + 52 + 12 + 40 + 28
# bytes per triangle: gathered vertices (36), faces and materials (16), normals
# and their CSR (~24), grid cell lists (~4 cells x 4) and a kd-tree (~64)
BYTES_PER_TRIANGLE = 36 + 16 + 24 + 16 + 64


def available_bytes():
    """MemAvailable of /proc/meminfo (None where there is none)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def check_memory(scene, cfg, available=None):
    """SceneError (exit 2) with the estimate if rendering would not fit in
    the memory available now, instead of an out-of-memory kill mid-run."""
    pixels = cfg.width * cfg.height
    per_pixel = (BYTES_PER_PIXEL + 4 * len(scene.spec.lights)
                 + sum({"N": 24, "P": 24, "id": 8}[a] for a in cfg.aovs))    # AOV + its EXR copy
    need = pixels * per_pixel + scene.faces.shape[0] * BYTES_PER_TRIANGLE
    available = available_bytes() if available is None else available
    if available is not None and need > 0.9 * available:
        raise SceneError(scene.path, "output.resolution",
                         f"{cfg.width}x{cfg.height} with {scene.faces.shape[0]:,} triangles needs about "
                         f"{_size(need)} of work memory; {_size(available)} are available")
    return need


def _size(n_bytes) -> str:
    return f"{n_bytes / 1024 ** 3:.1f} GiB" if n_bytes >= 1024 ** 3 else f"{n_bytes / 1024 ** 2:.0f} MiB"


class FrameWriteError(OSError):
    """A frame could not be written (disk full, directory gone, I/O error)."""


def render_animation(job: RenderJob, on_frame=None, warn=None, should_stop=None) -> dict:
    """Render the job's frames; returns the stats (also written to
    job.stats_path, merged by frame number with an earlier run's when
    resuming). Whatever ends the run (the last frame, Ctrl-C, SIGTERM, a
    failed write), the frames written so far are in stats.json, no frame is
    left half-written, and no claim or temporary file of this run remains.
    should_stop() is asked before every frame: an exception it returns ends
    the run there (Ctrl-C and SIGTERM, noted by the command line)."""
    scene, cfg = job.scene, job.cfg
    warn = warn or (lambda message: None)
    shading = shading_of(scene)
    todo = plan_frames(scene, job.out_dir, job.frames, job.resume, job.overwrite, cfg, warn)
    stale = {path for _, path in todo if path.exists()}     # to be rendered again (not whole)
    for directory in sorted({path.parent for _, path in todo}):
        writable_dir(directory, "frames")
        for name in remove_stale_temps(directory):
            warn(f"removed {directory / name}, left by a render that was killed")
    writable_file(job.stats_path, "stats.json")
    check_memory(scene, cfg)
    first_t = scene.time_of(todo[0][0] if todo else scene.frame_numbers[0])
    compile_s = warm_up(scene, shading, cfg, first_t) if todo else 0.0
    renderer = SceneRenderer(scene, cfg, shading) if todo else None
    rows, claimed = [], set()          # claimed: frames this run holds a claim on

    def write(path, result, row):
        t0 = time.perf_counter()
        channels = {"RGBA": result.rgba, "Z": result.z, **result.aovs}
        meta = {"frustrace:frame": int(row["frame"]), "frustrace:time": float(row["time"]),
                "Software": f"frustrace {VERSION}"}
        for k in ("interp_ms", "build_ms", "trace_ms", "shade_ms", "shadow_ms"):
            meta[f"frustrace:{k}"] = float(row[k])
        # the whole row: a frame written by a run that was then killed still
        # gets its line in stats.json (recovered_row) when a later run ends
        meta["frustrace:stats"] = json.dumps(row)
        try:
            write_exr(str(path), channels, meta, scene.spec.output.compression)
        except OSError as exc:
            raise FrameWriteError(f"cannot write frame {row['frame']} to {path}: "
                                  f"{exc.strerror or exc}") from None
        row["write_ms"] = (time.perf_counter() - t0) * 1e3   # read only after the write ends
        rows.append(row)                                      # in stats only once on disk
        release(path)
        claimed.discard(path)      # released: a later claim on it is another render's

    wall0 = time.perf_counter()
    ended = "complete"
    try:
        with ThreadPoolExecutor(max_workers=1) as writer:
            pending = []
            for frame, path in todo:
                while len(pending) > MAX_PENDING_WRITES:
                    pending.pop(0).result()
                stop = should_stop() if should_stop else None
                if stop is not None:
                    raise stop
                if not claim(path):          # another render (--resume, same directory) has it
                    continue
                if job.resume and path.exists() and path not in stale:
                    release(path)            # finished by another render since we planned
                    continue
                claimed.add(path)
                t = scene.time_of(frame)
                # a frame's images come from a ring of MAX_PENDING_WRITES + 2 sets, and
                # at most MAX_PENDING_WRITES writes are unfinished while it renders, so the
                # writer thread never sees its images overwritten
                interp_ms, result = renderer.render(t)
                row = frame_row(scene, frame, t, interp_ms, result)
                pending.append(writer.submit(write, path, result, row))
                if on_frame:
                    on_frame(row)
            for p in pending:
                p.result()
    except BaseException as exc:
        ended = "interrupted" if isinstance(exc, KeyboardInterrupt) else f"failed: {exc}"
        raise
    finally:
        for path in claimed:
            release(path)
        wall_s = time.perf_counter() - wall0
        run = {"started": time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(time.time() - wall_s)),
               "frames_rendered": len(rows), "wall_s": wall_s, "compile_s": compile_s, "ended": ended,
               **settings_of(cfg)}
        try:
            stats = write_stats(job.stats_path, scene, cfg, rows, run,
                                lambda f: frame_file(scene, job.out_dir, f), job.frames)
        except OSError as exc:
            message = f"cannot write {job.stats_path}: {exc.strerror or exc}"
            if ended == "complete":
                raise FrameWriteError(message) from None
            warn(message)                # the fault that ended the run is the one to report
    return stats


def write_stats(path: Path, scene, cfg, rows, run, file_of, frames) -> dict:
    """Merge this run into stats.json under a lock on its directory (two
    renders sharing a directory each add their frames): the earlier runs'
    frames whose files still exist, this run's, and the job's frames on disk
    that no stats.json lists (written by a run that was killed), recovered
    from their EXR headers. Written atomically."""
    fd = os.open(path.parent, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        previous = read_stats(path) or {"frames": [], "runs": []}
        previous["frames"] = [r for r in previous["frames"] if file_of(r["frame"]).exists()]
        listed = {r["frame"] for r in previous["frames"]} | {r["frame"] for r in rows}
        for f in frames:
            if f not in listed and file_of(f).exists():
                row = recovered_row(file_of(f))
                if row is not None:
                    previous["frames"].append(row)
        stats = merged_stats(previous, scene, cfg, rows, run)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(stats, indent=1))
        tmp.replace(path)
    finally:
        os.close(fd)                   # releases the lock
    return stats


def recovered_row(path: Path):
    """The stats row a frame carries in its header (frustrace:stats), marked
    recovered (its write_ms is unknown: 0); None for a file without one."""
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return None
    try:
        row = json.loads(inp.spec().getattribute("frustrace:stats") or "null")
    except ValueError:
        row = None
    finally:
        inp.close()
    if not isinstance(row, dict) or not all(isinstance(row.get(k), (int, float)) for k in PHASE_KEYS):
        return None
    return {**row, "recovered": True}


def frame_row(scene, frame, t, interp_ms, result) -> dict:
    """The stats.json entry of one rendered frame (SPEC section 5, and more)."""
    tm = result.timings
    rays = result.counters["rays"]
    return {"frame": frame, "time": t, "triangles": int(scene.faces.shape[0]), "rays": rays,
            "interp_ms": interp_ms, **tm, "write_ms": 0.0,
            "tri_tests": float(result.counters["tri_tests"]),
            "shadow_rays": result.counters["shadow_rays"],
            "shadow_rays_left_out": result.counters["shadow_rays_skipped"],   # facing away, dark, outside a penumbra
            "cells_visited": result.counters["cells"],   # kd-tree: nodes visited
            "fallback_rays": result.counters["fallback_rays"],
            **({"grid_dims": result.counters["grid_dims"]} if "grid_dims" in result.counters
               else {"kd_nodes": result.counters["kd_nodes"]}),
            "mrays_per_s": rays / max(tm["trace_ms"], 1e-9) / 1e3}


def settings_of(cfg: RenderConfig) -> dict:
    """What decides a frame's pixels, recorded with every run; the packet
    size the accelerator really used (the kd-tree's is always KD_PACKET)."""
    return {"accel": cfg.accel, "packet": KD_PACKET if cfg.accel == "kdtree" else cfg.packet,
            "threads": cfg.threads, "spp": cfg.spp, "shadows": cfg.shadows, "grid_density": cfg.grid_density}


PHASE_KEYS = ("interp_ms", "build_ms", "trace_ms", "shade_ms", "shadow_ms", "write_ms")


def read_stats(path: Path):
    """An earlier run's stats.json, or None if there is none or it is not
    one of ours (then this run's stats replace it)."""
    try:
        stats = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    frames = stats.get("frames") if isinstance(stats, dict) else None
    ok = isinstance(frames, list) and all(
        isinstance(r, dict) and isinstance(r.get("frame"), int)
        and all(isinstance(r.get(k), (int, float)) for k in PHASE_KEYS) for r in frames)
    return stats if ok else None


def merged_stats(previous, scene, cfg, rows, run) -> dict:
    """stats.json: this run's frames over an earlier run's, by frame number;
    the summary's medians over all of them, fps_wall and compile time of
    this run; every run listed with its settings."""
    frames = {r["frame"]: r for r in previous["frames"]}
    runs = [r for r in previous.get("runs", []) if isinstance(r, dict)]
    for r in rows:
        frames[r["frame"]] = {**r, "run": len(runs)}
    merged = [frames[k] for k in sorted(frames)]
    summary = summarize(merged, run["wall_s"], run["compile_s"])
    summary["fps_wall"] = len(rows) / run["wall_s"] if rows and run["wall_s"] > 0 else 0.0
    return {"scene": scene.path.name, "resolution": [cfg.width, cfg.height], **settings_of(cfg),
            "frames": merged, "runs": runs + [run], "summary": summary}


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
            "median_ms": {k: median_ms(rows, k) for k in PHASE_KEYS}}
