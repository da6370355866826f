"""stats.json: one row per frame, the runs that made them, and the fps
arithmetic of SPEC section 5 (medians over frames, compile time apart)."""
import fcntl
import json
import os
import socket
from pathlib import Path

import numpy as np

from raycore.accelerators import packet_of
from raycore.config import RenderConfig

from anim.render.output_dir import process_alive


def write_stats(path: Path, scene, cfg, rows, run, file_of, on_disk, verified=None) -> dict:
    """Merge this run into stats.json under a lock on its directory (two
    renders sharing a directory each add their frames): the earlier runs'
    frames whose files still exist, this run's, and the job's frames on disk
    (on_disk(): {frame: path}) that no stats.json lists (written by a run
    that was killed), recovered from their EXR headers, with the CRC-32 of
    those this run decoded whole (`verified`: {frame: crc}). Written
    atomically."""
    fd = os.open(path.parent, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        previous = read_stats(path) or {"frames": [], "runs": []}
        previous["frames"] = [r for r in previous["frames"] if file_of(r["frame"]).exists()]
        listed = {r["frame"] for r in previous["frames"]} | {r["frame"] for r in rows}
        recovered = [row for f, frame_path in sorted(on_disk().items()) if f not in listed
                     for row in [recovered_row(frame_path)] if row is not None and not _writer_alive(row)]
        previous["runs"] = [r for r in previous.get("runs", []) if isinstance(r, dict)]
        for row in recovered:
            if (verified or {}).get(row["frame"]) is not None:
                row["crc32"] = verified[row["frame"]]
        recovered_runs(previous["runs"], recovered)
        previous["frames"] += recovered
        stats = merged_stats(previous, scene, cfg, rows, run)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(stats, indent=1))
        tmp.replace(path)
    finally:
        os.close(fd)                   # releases the lock
    return stats


def recovered_row(path: Path):
    """The stats row a frame carries in its header (frustrace:stats), marked
    recovered (its write_ms is unknown: None); None for a file without one."""
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return None
    try:
        row = json.loads(inp.spec().getattribute("frustrace:stats") or "null")
        run = json.loads(inp.spec().getattribute("frustrace:run") or "null")
    except ValueError:
        row = run = None
    finally:
        inp.close()
    if not isinstance(row, dict) or not all(isinstance(row.get(k), (int, float)) for k in PHASE_KEYS):
        return None
    # the header was written before the write ended: its write time is unknown
    return {**row, "write_ms": None, "recovered": True,
            **({"run_info": run} if isinstance(run, dict) else {})}


def _writer_alive(row) -> bool:
    """Whether the run that wrote a recovered frame is still rendering here
    (another render sharing the directory): its own stats come when it ends."""
    info = row.get("run_info") or {}
    return (info.get("host") == socket.gethostname() and isinstance(info.get("pid"), int)
            and info["pid"] != os.getpid() and process_alive(info["pid"]))


def recovered_runs(runs: list, recovered: list) -> None:
    """Give the recovered rows (recovered_row) their run: a run whose
    frames are on disk but which never wrote stats.json (it was killed) is
    listed as ended "killed", with its start and settings from the frames'
    headers and the number of its frames found."""
    by_start = {}
    for row in recovered:
        info = row.pop("run_info", None)
        if info is None:
            continue
        key = json.dumps(info, sort_keys=True)
        if key not in by_start:
            by_start[key] = len(runs)
            runs.append({**info, "frames_rendered": 0, "ended": "killed", "recovered": True})
        row["run"] = by_start[key]
        runs[row["run"]]["frames_rendered"] += 1


def frame_row(scene, frame, t, interp_ms, result) -> dict:
    """The stats.json entry of one rendered frame (SPEC section 5, and more)."""
    tm = result.timings
    rays = result.counters["rays"]
    # triangles: the world's, every instance's counted (an instanced world holds its prototypes once)
    return {"frame": frame, "time": t, "triangles": int(scene.flat_triangles), "rays": rays,
            "interp_ms": interp_ms, **tm, "write_ms": 0.0,
            "tri_tests": float(result.counters["tri_tests"]),
            "shadow_rays": result.counters["shadow_rays"],
            "shadow_rays_left_out": result.counters["shadow_rays_skipped"],   # facing away, dark, outside a penumbra
            "cells_visited": result.counters["cells"],   # kd-tree and BVH: nodes visited
            "fallback_rays": result.counters["fallback_rays"],
            # the structures this frame built: grid cells, kd-tree nodes, BVH refit and rebuilds
            **{k: result.counters[k] for k in STRUCTURE_KEYS if k in result.counters},
            # under an error budget: the cap in force, and the camera rays not
            # spent against plain spp at that cap everywhere (negative when most
            # pixels took the cap: a capped pixel also keeps its earlier samples)
            **({"spp_cap": result.counters["spp_cap"],
                "rays_left_out": result.counters["rays_left_out"],
                "spp_mean": result.counters["adaptive_spp_mean"]} if "rays_left_out" in result.counters else {}),
            # under motion blur or a thin lens: the shutter times and lens positions
            # the passes took, and how often (and how long) the structures were built
            **({"time_samples": result.counters["time_samples"], "lens_samples": result.counters["lens_samples"],
                "passes": result.counters["passes"], "builds": result.counters["builds"],
                "rebuild_ms_per_pass": tm["build_ms"] / max(result.counters["passes"], 1)}
               if "time_samples" in result.counters else {}),
            # RGB values that half floats cannot hold (they are written as +inf)
            **({"half_overflow": n_over} if (n_over := half_overflow(result.rgba)) else {}),
            "mrays_per_s": rays / max(tm["trace_ms"], 1e-9) / 1e3}


# the smallest float32 that rounds to +inf in half precision (65504 is the largest half)
HALF_INF_FROM = 65520.0


def half_overflow(rgba) -> int:
    """How many R, G, B values of a frame become +inf when stored as half."""
    # one contiguous pass first (alpha is at most 1, so it never decides it):
    # the strided RGB view alone took 8 ms a frame at 1024^2, this 0.3 ms
    if rgba.size == 0 or not rgba.max() >= HALF_INF_FROM:
        return 0
    return int(np.count_nonzero(rgba[..., :3] >= HALF_INF_FROM))


def frame_metadata(row: dict, version: str, run_info: dict) -> dict:
    """The EXR header attributes of a frame (both paths write the same);
    run_info: the run's start and settings, for stats.recovered_runs."""
    meta = {"frustrace:frame": int(row["frame"]), "frustrace:time": float(row["time"]),
            "Software": f"frustrace {version}"}
    for k in ("interp_ms", "build_ms", "trace_ms", "shade_ms", "shadow_ms"):
        meta[f"frustrace:{k}"] = float(row[k])
    # the whole row: a frame written by a run that was then killed still gets
    # its line in stats.json (stats.recovered_row) when a later run ends
    meta["frustrace:stats"] = json.dumps(row)
    meta["frustrace:run"] = json.dumps(run_info)
    return meta


STRUCTURE_KEYS = ("grid_dims", "kd_nodes", "bvh_build_ms", "bvh_refit_ms", "bvh_top_ms", "bvh_rebuilt",
                  "bvh_sah_growth")


def settings_of(cfg: RenderConfig) -> dict:
    """What decides a frame's pixels, recorded with every run; the packet
    size the accelerator really used (the kd-tree's and the BVH's are 8x8)."""
    return {"accel": cfg.accel, **({"accel_choice": cfg.accel_choice} if cfg.accel_choice else {}),
            "shadow_accel": cfg.shadow_structure,
            "packet": packet_of(cfg.accel, cfg.packet),
            "threads": cfg.threads, "spp": cfg.spp, "shadows": cfg.shadows, "grid_density": cfg.grid_density,
            **({"max_error": cfg.max_error} if cfg.max_error > 0 else {}),
            **({"shutter": cfg.shutter, "shutter_position": cfg.shutter_position} if cfg.shutter > 0 else {}),
            **({"aperture_radius": cfg.aperture_radius, "focus_distance": cfg.focus_distance or None}
               if cfg.aperture_radius > 0 else {})}


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
        and all(isinstance(r.get(k), (int, float)) or (k == "write_ms" and r.get("recovered") and r.get(k) is None)
                for k in PHASE_KEYS) for r in frames)
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
    summary["warm_up_s"] = run.get("warm_up_s", run["compile_s"])
    summary["fps_wall"] = len(rows) / run["wall_s"] if rows and run["wall_s"] > 0 else 0.0
    for key in ("peak_rss_bytes", "bytes_per_triangle"):        # this run's, when it rendered here
        if run.get(key) is not None:
            summary[key] = run[key]
    return {"scene": scene.path.name, "scene_file": str(Path(scene.path).resolve()), "resolution": [cfg.width, cfg.height], **settings_of(cfg),
            "frames": merged, "runs": runs + [run], "summary": summary}


def median_ms(rows, *keys, missing=0.0):
    """Median over frames of the sum of the given phase timings, over the
    frames that measured them all (a recovered frame's write_ms is unknown,
    None); `missing` when no frame did."""
    sums = [sum(r[k] for k in keys) for r in rows if all(r.get(k) is not None for k in keys)]
    return float(np.median(sums)) if sums else missing


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
            # null where no frame measured the phase (every frame recovered
            # from killed runs has an unknown write time): unknown, not 0
            "median_ms": {k: median_ms(rows, k, missing=None) for k in PHASE_KEYS}}


def stats_owner_problem(previous, scene):
    """Why an existing stats.json may not take this scene's frames ('' if it
    may): it belongs to another scene file. Two scenes in one stats.json
    kept one frame 0 and switched its `scene` silently."""
    if not previous:
        return ""
    mine = str(Path(scene.path).resolve())
    theirs = previous.get("scene_file")
    if theirs is None:                  # written before scene_file was recorded
        same = previous.get("scene") == scene.path.name
    else:
        same = theirs == mine
    if same:
        return ""
    return (f"holds the stats of another scene ({theirs or previous.get('scene')}); render {scene.path.name} "
            "into another directory, or give it its own --stats PATH")
