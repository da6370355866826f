"""`frustrace bench`: fps per phase on built-in scenes, medians over frames.

Frames are rendered exactly as `render` does (interpolate, rebuild, trace,
shadow, shade) but not written; compile time is spent in a warm-up first and
reported apart. Rows follow ../shared/SPEC.md section 5.
"""
import tempfile
import time
from pathlib import Path

import numpy as np

from anim.errors import SceneError
from anim.procedural import SCENES as PROCEDURAL
from anim.scene import AnimatedScene
from raycore.config import RenderConfig
from raycore.frame import CameraPose, FrameBuffers, Geometry, render_frame
from raycore.mesh import vertex_face_csr

from .pipeline import shading_of

DEMO = Path(__file__).resolve().parent.parent / "assets" / "demo" / "anim.yaml"
SCENE_NAMES = ("demo", *PROCEDURAL)


def scene_file(name: str, workdir: Path) -> Path:
    """Path of a built-in scene's anim.yaml, generating it if procedural."""
    if name == "demo":
        if not DEMO.is_file():
            raise SceneError(DEMO, "", "the demo scene ships with the source tree only")
        return DEMO
    if name not in PROCEDURAL:
        raise SceneError("--scene", "", f"unknown scene {name!r}; built-in: {', '.join(SCENE_NAMES)}")
    out = workdir / name
    PROCEDURAL[name](out)
    return out / "anim.yaml"


def bench_scene(path: Path, name: str, res: int, n_frames: int, packet: int, threads: int) -> dict:
    scene = AnimatedScene(path)
    spec = scene.spec
    cfg = RenderConfig(width=res, height=res, packet=packet, threads=threads,
                       spp=spec.render.spp, shadows=spec.render.shadows,
                       grid_density=spec.render.grid_density,
                       background=tuple(spec.render.background), ambient=spec.render.ambient)
    shading = shading_of(scene)
    vf_start, vf_faces = vertex_face_csr(scene.faces, scene.n_vertices)
    buffers = FrameBuffers(res, res, shading.lights.shape[0], packet)
    frames = scene.frame_numbers[:max(1, n_frames)]
    rows = []
    for i, frame in enumerate([frames[0]] + frames):       # first pass = warm-up
        t = scene.time_of(frame)
        t0 = time.perf_counter()
        vertices = scene.vertices_at(t)
        eye, look_at, up, fov = scene.camera_at(t)
        interp_ms = (time.perf_counter() - t0) * 1e3
        geom = Geometry(vertices, scene.faces, scene.tri_material, scene.uvs, vf_start, vf_faces)
        result = render_frame(geom, shading, CameraPose(eye, look_at, up, fov), cfg, buffers)
        if i > 0:
            rows.append({"interp_ms": interp_ms, **result.timings,
                         "tri_tests": result.counters["tri_tests"], "rays": result.counters["rays"]})

    def med(*keys):
        return float(np.median([sum(r[k] for k in keys) for r in rows]))
    raycast = med("interp_ms", "build_ms", "trace_ms")
    full = med("interp_ms", "build_ms", "trace_ms", "shade_ms", "shadow_ms")
    return {"scene": name, "accel": "grid", "packet": packet, "threads": threads,
            "triangles": int(scene.faces.shape[0]), "resolution": res, "frames": len(rows),
            "interp_ms": med("interp_ms"), "build_ms": med("build_ms"), "trace_ms": med("trace_ms"),
            "shade_ms": med("shade_ms"), "shadow_ms": med("shadow_ms"),
            "fps_raycast": 1000.0 / raycast, "fps_full": 1000.0 / full,
            "mrays_per_s": res * res / med("trace_ms") / 1e3, "tri_tests": med("tri_tests")}


def run_bench(names, res, n_frames, packets, threads):
    with tempfile.TemporaryDirectory(prefix="frustrace-bench-") as tmp:
        paths = {n: scene_file(n, Path(tmp)) for n in names}
        return [bench_scene(paths[n], n, res, n_frames, p, threads) for n in names for p in packets]
