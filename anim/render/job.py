"""A render job: the frames of one scene written as EXR files, with stats,
rendered in this process or on a Dask cluster (cluster.py).

Writing a frame goes through a writer thread, but the render of the next frame
waits for it (MAX_PENDING_WRITES = 0): on this 2-core machine kind the EXR
write holds a core, and numba's statically split parallel regions then stall
on it, slowing the render phases by up to a third, which costs more than the
overlap gains. Raise the constant on machines with cores to spare.
"""
import os
import socket
import time
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

import raycore
from anim.errors import SceneError
from anim.memory import peak_report
from anim.scene import AnimatedScene
from raycore.config import RenderConfig
from raycore.images.image_io import temp_path, write_exr

from anim.render.compile_watch import watching
from anim.render.frame_files import existing_frames, frame_file, plan_frames
from anim.render.output_dir import claim, file_crc32, release, remove_stale_temps
from anim.render.paths import writable_dir, writable_file
from anim.render.renderer import SceneRenderer, check_memory
from anim.render.warm_up import warm_up
from anim.render.settings import shading_of
from anim.render.stats import frame_metadata, frame_row, read_stats, settings_of, stats_owner_problem, write_stats

VERSION = raycore.__version__
MAX_PENDING_WRITES = 0


class RenderJob(NamedTuple):
    scene: AnimatedScene
    cfg: RenderConfig
    frames: list
    out_dir: Path
    stats_path: Path
    resume: bool
    overwrite: bool
    chunk: int = 4            # cluster: consecutive frames per task


class FrameWriteError(OSError):
    """A frame could not be written (disk full, directory gone, I/O error)."""


class FrameRenderError(RuntimeError):
    """A frame could not be rendered (on a cluster worker: the error it raised)."""


def render_animation(job: RenderJob, on_frame=None, warn=None, should_stop=None, client=None,
                     on_compile=None) -> dict:
    """Render the job's frames, here or, with a Dask `client`, on its
    cluster; returns the stats (also written to job.stats_path, merged by
    frame number with an earlier run's when resuming). Whatever ends the run
    (the last frame, Ctrl-C, SIGTERM, a failed write or task), the frames
    written so far are in stats.json, no frame is left half-written, and no
    claim or temporary file of this run remains. should_stop() is asked
    before every frame: an exception it returns ends the run there (Ctrl-C
    and SIGTERM, noted by the command line). on_compile(watch) is called as
    the warm-up compiles each kernel (a first run only; compile_watch.py)."""
    scene, cfg = job.scene, job.cfg
    warn = warn or (lambda message: None)
    previous = read_stats(job.stats_path)
    problem = stats_owner_problem(previous, scene)
    if problem:
        raise SceneError(job.stats_path, "", problem)
    shading = None
    if client is None:
        # refused before any file or folder is made: a texture that cannot be
        # read, a render that would not fit in memory
        shading = shading_of(scene)
        check_memory(scene, cfg)
    checksums = {r["frame"]: r["crc32"] for r in (previous or {}).get("frames", [])
                 if isinstance(r.get("crc32"), int)} if job.resume else {}
    todo = plan_frames(scene, job.out_dir, job.frames, job.resume, job.overwrite, cfg, warn, checksums)
    stale = todo.stale                   # existing files to be rendered again (not whole), filled as checked
    directory = todo.directory
    if todo.first() is not None:
        writable_dir(directory, "frames")
    # also when every frame is done: a render killed after writing its last
    # frame but before releasing that frame's claim left the claim behind
    if directory is not None and directory.is_dir():
        removed = remove_stale_temps(directory)
        if len(removed) == 1:
            warn(f"removed {directory / removed[0]}, left by a render that was killed")
        elif removed:                    # one line, however many claims a killed cluster render left
            warn(f"removed {len(removed)} claims and temporary files in {directory}, left by a render "
                 f"that was killed ({', '.join(sorted(removed)[:3])}, ...)")
    writable_file(job.stats_path, "stats.json")
    rows, claimed = [], set()          # claimed: frames this run holds a claim on

    def take(frame, path) -> bool:
        """Claim a frame before it is rendered; False if it is not ours to do."""
        if not claim(path):          # another render (--resume, same directory) has it
            return False
        if job.resume and path.exists() and path not in stale:
            release(path)            # finished by another render since we planned
            return False
        claimed.add(path)
        return True

    overflow_told = []

    def done(path, row):
        if row.get("half_overflow") and not overflow_told:
            overflow_told.append(row["frame"])
            warn(f"frame {row['frame']}: {row['half_overflow']:,} RGB values are above 65504, the largest half "
                 "float, and are written as +inf (lower the lights' intensity; stats.json counts them per "
                 "frame as half_overflow)")
        rows.append(row)             # in stats only once on disk
        release(path)
        claimed.discard(path)        # released: a later claim on it is another render's

    wall0 = time.perf_counter()
    started = time.strftime("%Y-%m-%dT%H:%M:%S")
    # in every frame's header: a frame of a run killed before its stats were
    # written brings its run back into stats.json (stats.recovered_runs)
    run_info = {"started": started, "host": socket.gethostname(), "pid": os.getpid(), **settings_of(cfg)}
    ended, extra = "complete", {"compile_s": 0.0, "warm_up_s": 0.0}
    try:
        if client is None:
            _render_here(job, todo, take, done, on_frame, should_stop, extra, run_info, shading, on_compile)
        else:
            extra.update(_render_on_cluster(job, todo, take, done, on_frame, should_stop, client, run_info))
    except BaseException as exc:
        ended = "interrupted" if isinstance(exc, KeyboardInterrupt) else f"failed: {exc}"
        raise
    finally:
        for path in claimed:
            release(path)
        # the wall clock of the frames: the warm-up (compile) is reported apart;
        # on a cluster the workers' own warm-ups fall inside it
        wall_s = time.perf_counter() - wall0 - extra["warm_up_s"]
        if client is None:               # this process's memory (a cluster's workers report none)
            extra.update(peak_report(scene.flat_triangles, scene.key_bytes))
        run = {"started": started, "frames_rendered": len(rows), "wall_s": wall_s, **extra, "ended": ended, **settings_of(cfg)}
        try:
            stats = write_stats(job.stats_path, scene, cfg, rows, run,
                                lambda f: frame_file(scene, job.out_dir, f),
                                lambda: existing_frames(scene, job.out_dir, job.frames), todo.verified)
        except OSError as exc:
            message = f"cannot write {job.stats_path}: {exc.strerror or exc}"
            if ended == "complete":
                raise FrameWriteError(message) from None
            warn(message)                # the fault that ended the run is the one to report
    return stats


def _render_here(job, todo, take, done, on_frame, should_stop, extra, run_info, shading, on_compile=None) -> None:
    """Frames in this process, written by a writer thread; the compile
    warm-up's seconds go into extra["warm_up_s"] as soon as they are known,
    the seconds numba spent compiling in it into extra["compile_s"]."""
    scene, cfg = job.scene, job.cfg
    if todo.first() is None:
        return
    renderer = SceneRenderer(scene, cfg, shading, MAX_PENDING_WRITES)
    with watching(on_compile) as watch:
        # the warm-up builds the frames' own structures (renderer.structures)
        extra["warm_up_s"], helper_compiled = warm_up(scene, shading, cfg, scene.time_of(todo.first()[0]),
                                                      structures=renderer.structures)
    extra["compiled"] = watch.seconds()          # {kernel: s}: empty when the cache had them all
    extra["compile_s"] = float(sum(extra["compiled"].values()))
    if helper_compiled:                          # a cold cache's other half (compile_helper.py)
        extra["compiled_by_helper"] = helper_compiled
    if on_compile is not None and watch.done:
        on_compile(None)

    def write(path, result, row):
        t0 = time.perf_counter()
        channels = {"RGBA": result.rgba, "Z": result.z, **result.aovs}
        try:
            write_exr(str(path), channels, frame_metadata(row, VERSION, run_info), scene.spec.output.compression)
        except OSError as exc:
            raise FrameWriteError(f"cannot write frame {row['frame']} to {path}: "
                                  f"{exc.strerror or exc}") from None
        row["write_ms"] = (time.perf_counter() - t0) * 1e3   # read only after the write ends
        row["crc32"] = file_crc32(path)                      # what --resume compares (output_dir.whole_frame)
        done(path, row)

    with ThreadPoolExecutor(max_workers=1) as writer:
        pending = []
        for frame, path in todo:
            while len(pending) > MAX_PENDING_WRITES:
                pending.pop(0).result()
            stop = should_stop() if should_stop else None
            if stop is not None:
                raise stop
            if not take(frame, path):
                continue
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


def _render_on_cluster(job, todo, take, done, on_frame, should_stop, client, run_info) -> dict:
    """Frames on the client's cluster in chunks of consecutive frames; each
    frame comes back as EXR bytes and is written here, atomically. Returns
    the run's per-worker figures. A Ctrl-C (should_stop) or a failed task
    cancels every chunk still out."""
    import dataclasses

    from concurrent.futures import CancelledError

    from distributed import as_completed

    from anim.render.cluster import TASK_RETRIES, bundle_scene, chunks_of, render_chunk
    scene, cfg = job.scene, job.cfg
    mine = [(f, p) for f, p in todo if take(f, p)]
    paths = dict(mine)
    if not mine:
        return {"workers": {}}
    data = bundle_scene(scene)
    bundle = client.scatter(data, broadcast=True, hash=False)
    cfg_fields = dataclasses.asdict(cfg)

    def submit(chunk):
        return client.submit(render_chunk, bundle, cfg_fields, chunk, scene.spec.output.compression, VERSION,
                             run_info, retries=TASK_RETRIES, pure=False)
    chunk_of = {}
    for c in chunks_of([f for f, _ in mine], max(1, job.chunk)):
        chunk_of[submit(c)] = (c, 0)
    futures = list(chunk_of)
    workers = {}
    try:
        pending = as_completed(futures)
        for future in pending:
            stop = should_stop() if should_stop else None
            if stop is not None:
                raise stop
            try:
                results = future.result()
            except CancelledError:
                # the scene's bundle was lost with the workers that held it (one that joined after
                # the scatter may have had none): sent again, and the chunk with it
                chunk, tries = chunk_of[future]
                if tries >= TASK_RETRIES:
                    raise FrameRenderError(f"frames {chunk[0]}..{chunk[-1]}: cancelled by the cluster "
                                           f"{tries + 1} times (workers lost)") from None
                bundle = client.scatter(data, broadcast=True, hash=False)
                again = submit(chunk)
                chunk_of[again] = (chunk, tries + 1)
                futures.append(again)
                pending.add(again)
                continue
            except Exception as exc:     # the task's error, raised again here by Dask
                raise FrameRenderError(str(exc)) from None
            for frame, data, row in results:
                path = paths[frame]
                t0 = time.perf_counter()
                _write_bytes(path, data, frame)
                row["write_ms"] = (time.perf_counter() - t0) * 1e3
                row["bytes"] = len(data)
                row["crc32"] = zlib.crc32(data)
                compile_s = row.pop("worker_compile_s")
                w = workers.setdefault(row["worker"], {"compile_s": compile_s, "frames": 0, "busy_ms": 0.0})
                w["frames"] += 1
                w["busy_ms"] += sum(row[k] for k in ("interp_ms", "build_ms", "trace_ms", "shade_ms",
                                                     "shadow_ms", "encode_ms"))
                done(path, row)
                if on_frame:
                    on_frame(row)
    finally:
        client.cancel([f for f in futures if not f.done()])
    for w in workers.values():
        w["fps"] = w["frames"] / (w.pop("busy_ms") / 1e3) if w["frames"] else 0.0
    return {"workers": workers}


def _write_bytes(path: Path, data: bytes, frame: int) -> None:
    """An encoded frame into place: temporary file, then rename."""
    tmp = temp_path(str(path))
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except OSError as exc:
        raise FrameWriteError(f"cannot write frame {frame} to {path}: {exc.strerror or exc}") from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
