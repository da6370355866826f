"""A render job: the frames of one scene written as EXR files, with stats.

Writing a frame goes through a writer thread, but the render of the next frame
waits for it (MAX_PENDING_WRITES = 0): on this 2-core machine kind the EXR
write holds a core, and numba's statically split parallel regions then stall
on it, slowing the render phases by up to a third, which costs more than the
overlap gains. Raise the constant on machines with cores to spare.
"""
import json
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

from anim.scene import AnimatedScene
from raycore.config import RenderConfig
from raycore.image_io import write_exr

from .frame_files import frame_file, plan_frames
from .output_dir import claim, release, remove_stale_temps
from .paths import writable_dir, writable_file
from .renderer import SceneRenderer, check_memory, warm_up
from .settings import shading_of
from .stats import frame_row, settings_of, write_stats

VERSION = "0.1.0"


MAX_PENDING_WRITES = 0


class RenderJob(NamedTuple):
    scene: AnimatedScene
    cfg: RenderConfig
    frames: list
    out_dir: Path
    stats_path: Path
    resume: bool
    overwrite: bool


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
    renderer = SceneRenderer(scene, cfg, shading, MAX_PENDING_WRITES) if todo else None
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
