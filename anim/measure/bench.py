"""`frustrace bench` rows: fps per phase on built-in scenes, medians over frames.

Frames are rendered exactly as `render` does (interpolate, rebuild, trace,
shadow, shade) and written to one temporary EXR (write_ms); compile time is
spent in a warm-up first and reported apart. Rows follow SPEC section 5, plus
interp_ms, write_ms and shadow_mrays_per_s; with --peers, a row per peer
(anim/measure/peers.py) with hit_agreement, and vs_best_peer on frustrace's rows.
"""
import tempfile
import time
from pathlib import Path

import numpy as np

from anim import builtin
from anim.errors import SceneError
from anim.render.renderer import SceneRenderer
from anim.render.warm_up import warm_up
from anim.render.settings import config_of, shading_of
from anim.render.stats import STRUCTURE_KEYS, fps_of, median_ms
from anim.scene import AnimatedScene
from raycore.config import SHADOW_ACCEL
from raycore.accelerators import packet_of
from raycore.frame import CameraPose
from raycore.images.image_io import write_exr

SCENE_NAMES = tuple(builtin.ALL)


def scene_file(name: str, workdir: Path) -> Path:
    """A built-in scene's anim.yaml written into workdir/name (generated, or
    the demo's shipped files copied), or a user's scene file as it is."""
    if name not in builtin.ALL and Path(name).is_file():
        return Path(name)
    if name not in builtin.ALL:
        raise SceneError("--scene", "", f"unknown scene {name!r}; built-in: {', '.join(SCENE_NAMES)}")
    return builtin.get(name).write(workdir / name)


def warm_up_frames(scene) -> list:
    """The two frames rendered before timing: the second takes the per-frame
    paths the first does not (the BVH's refit, a moved grid), whose first
    call loads or compiles them (a refit's 7 ms cache load made a 2-frame
    median refit 3 ms, not 0.04)."""
    numbers = scene.frame_numbers
    return [numbers[0], numbers[min(1, len(numbers) - 1)]]


def bench_scene(path: Path, name: str, res: int, n_frames: int, packet: int, threads: int,
                accel: str = "grid", workdir: Path = None, depth_out: list = None,
                shadow_accel: str = SHADOW_ACCEL) -> dict:
    """One row: medians over n_frames frames (after a warm-up frame). With
    depth_out, the first measured frame's Z is appended to it. The BVH's
    first build is timed on its own (the warm-up frame's compile aside:
    a second renderer builds it again) and reported per 100K triangles."""
    scene = AnimatedScene(path)
    cfg = config_of(scene, width=res, height=res, packet=packet, threads=threads, aovs=(), accel=accel,
                    shadow_accel=shadow_accel)
    shading = shading_of(scene)
    frames = scene.frame_numbers[:max(1, n_frames)]
    warm_up(scene, shading, cfg, scene.time_of(frames[0]))    # a cold cache: compiled in two processes
    renderer = SceneRenderer(scene, cfg, shading)
    rows = []
    for i, frame in enumerate([*warm_up_frames(scene), *frames], start=-1):
        interp_ms, result = renderer.render(scene.time_of(frame))
        t0 = time.perf_counter()
        if workdir is not None:          # the frame's EXR, as `render` writes it
            write_exr(str(workdir / "bench_frame.exr"), {"RGBA": result.rgba, "Z": result.z}, {},
                      scene.spec.output.compression)
        write_ms = (time.perf_counter() - t0) * 1e3
        if i == 1 and depth_out is not None:
            depth_out.append(result.z.reshape(-1).copy())
        if i > 0:
            rows.append({"interp_ms": interp_ms, **result.timings, "write_ms": write_ms,
                         "tri_tests": result.counters["tri_tests"],
                         "shadow_rays": result.counters["shadow_rays"],
                         **{k: result.counters[k] for k in STRUCTURE_KEYS if k in result.counters}})
    row = _row(name, accel, packet_of(accel, packet), threads, scene, res, rows)
    row["shadow_accel"] = shadow_accel
    if "bvh" in (accel, shadow_accel):
        row.update(bvh_build_costs(scene, renderer, rows))
    return row


def bvh_build_costs(scene, renderer, rows):
    """The BVH's full build (all trees, on the first frame's triangles;
    the median of five: the build is on two threads, which a busy host
    slows unevenly) and median refit of the moving trees, in ms and in ms
    per 100K triangles;
    how often a refit tree was rebuilt, and its largest SAH growth."""
    trees = renderer.structures.scene_bvh()
    tri_verts = renderer.structures.corners()
    builds = []
    for _ in range(5):
        t0 = time.perf_counter()
        trees.build_all(tri_verts)
        builds.append((time.perf_counter() - t0) * 1e3)
    n_moving = sum(len(g) for g, m in zip(trees.groups, trees.moving) if m)
    n_all = scene.faces.shape[0]
    refit = median_ms(rows, "bvh_refit_ms")
    return {"bvh_build_ms": float(np.median(builds)),
            "bvh_build_ms_per_100k": float(np.median(builds)) * 1e5 / max(n_all, 1),
            "bvh_refit_ms": refit, "moving_triangles": n_moving,
            "bvh_refit_ms_per_100k": refit * 1e5 / n_moving if n_moving else 0.0,
            "bvh_rebuilds": int(sum(r.get("bvh_rebuilt", 0) for r in rows)),
            "bvh_max_sah_growth": max((r.get("bvh_sah_growth", 1.0) for r in rows), default=1.0)}


def _row(name, accel, packet, threads, scene, res, rows):
    """A table row from per-frame timings."""
    fps_raycast, fps_full = fps_of(rows)
    return {"scene": name, "accel": accel, "packet": packet, "threads": threads,
            "triangles": int(scene.faces.shape[0]), "resolution": res, "frames": len(rows),
            **{k: median_ms(rows, k) for k in ("interp_ms", "build_ms", "trace_ms", "shade_ms",
                                              "shadow_ms", "write_ms")},
            "fps_raycast": fps_raycast, "fps_full": fps_full,
            "mrays_per_s": res * res / median_ms(rows, "trace_ms") / 1e3,
            # shadow rays actually cast (facing-away points and dark lights cost none)
            "shadow_mrays_per_s": (median_ms(rows, "shadow_rays") / median_ms(rows, "shadow_ms") / 1e3
                                   if median_ms(rows, "shadow_ms") > 0 else 0.0),
            "tri_tests": median_ms(rows, "tri_tests")}


def bench_peer(peer, path: Path, name: str, res: int, n_frames: int, threads: int,
               interp_ms: float, reference_z=None) -> dict:
    """A row for a peer (anim/measure/peers.py) on the same frames as bench_scene: no
    shading, no write. interp_ms is frustrace's median for these frames (the
    same interpolation; timed here it would also time the peers' idle thread
    pools, which spin for a while after each call). With reference_z
    (frustrace's Z of the first measured frame), the share of pixels whose
    hit or miss agrees goes into the row."""
    from anim.measure.peers import instanced_parts, peer_frame
    scene = AnimatedScene(path)
    lights = shading_of(scene).lights
    frames = scene.frame_numbers[:max(1, n_frames)]
    rows = []
    for i, frame in enumerate([frames[0], *frames]):       # first pass = warm-up
        t = scene.time_of(frame)
        timings, depth = peer_frame(peer, scene.vertices_at(t), scene.faces,
                                    CameraPose(*scene.camera_at(t)), res, res, lights, instanced_parts(scene, t))
        if i == 1 and reference_z is not None:
            agree = float(np.mean(np.isfinite(depth) == np.isfinite(reference_z)))
        if i > 0:
            rows.append({"interp_ms": interp_ms, **timings, "write_ms": 0.0, "tri_tests": 0})
    own = hasattr(peer, "build_instanced") and any(o.instances is not None for o in scene.objects)
    row = {**_row(name, peer.name + (" (instances)" if own else ""), 0, threads, scene, res, rows), "peer": True}
    if reference_z is not None:
        row["hit_agreement"] = agree
    return row


def run_bench(names, res, n_frames, packets, threads, accels=("grid",), peers=(), shadow_accels=(SHADOW_ACCEL,)):
    """Rows for every scene, structure and packet size, then one per peer
    and scene; frustrace rows get vs_best_peer (fps_full over the best
    peer's fps_full on that scene)."""
    with tempfile.TemporaryDirectory(prefix="frustrace-bench-") as tmp:
        paths = {n: scene_file(n, Path(tmp)) for n in names}
        rows = []
        for n in names:
            label = n if n in builtin.ALL else Path(n).name      # a scene file: by its name
            depth = []
            for accel in accels:      # the kd-tree's and the BVH's packets are always 8x8
                for p in (packets if accel == "grid" else packets[:1]):
                    for shadow in shadow_accels:
                        rows.append(bench_scene(paths[n], label, res, n_frames, p, threads, accel, Path(tmp),
                                                depth, shadow))
            peer_rows = [bench_peer(peer, paths[n], label, res, n_frames, threads, rows[-1]["interp_ms"],
                                    depth[0]) for peer in peers]
            best = max((r["fps_full"] for r in peer_rows), default=0.0)
            if best > 0:
                for r in rows:
                    if r["scene"] == label:
                        r["vs_best_peer"] = r["fps_full"] / best
            rows += peer_rows
        return rows
