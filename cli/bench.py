"""`frustrace bench`: fps per phase on built-in scenes, medians over frames.

Frames are rendered exactly as `render` does (interpolate, rebuild, trace,
shadow, shade) but not written; compile time is spent in a warm-up first and
reported apart. Rows follow ../shared/SPEC.md section 5.
"""
import tempfile
from pathlib import Path

from anim.errors import SceneError
from anim import builtin
from anim.scene import AnimatedScene

from raycore.frame import KD_PACKET

from .pipeline import SceneRenderer, config_of, fps_of, median_ms, shading_of

DEMO = Path(__file__).resolve().parent.parent / "assets" / "demo" / "anim.yaml"
SCENE_NAMES = ("demo", *builtin.SCENES)


def scene_file(name: str, workdir: Path) -> Path:
    """Path of a built-in scene's anim.yaml, generating it if procedural."""
    if name == "demo":
        if not DEMO.is_file():
            raise SceneError(DEMO, "", "the demo scene ships with the source tree only")
        return DEMO
    if name not in builtin.SCENES:
        raise SceneError("--scene", "", f"unknown scene {name!r}; built-in: {', '.join(SCENE_NAMES)}")
    out = workdir / name
    return builtin.get(name).write(out)


def bench_scene(path: Path, name: str, res: int, n_frames: int, packet: int, threads: int,
                accel: str = "grid") -> dict:
    scene = AnimatedScene(path)
    cfg = config_of(scene, width=res, height=res, packet=packet, threads=threads, aovs=(), accel=accel)
    renderer = SceneRenderer(scene, cfg, shading_of(scene))
    frames = scene.frame_numbers[:max(1, n_frames)]
    rows = []
    for i, frame in enumerate([frames[0]] + frames):       # first pass = warm-up
        interp_ms, result = renderer.render(scene.time_of(frame))
        if i > 0:
            rows.append({"interp_ms": interp_ms, **result.timings,
                         "tri_tests": result.counters["tri_tests"]})
    fps_raycast, fps_full = fps_of(rows)
    return {"scene": name, "accel": accel, "packet": packet if accel == "grid" else KD_PACKET, "threads": threads,
            "triangles": int(scene.faces.shape[0]), "resolution": res, "frames": len(rows),
            **{k: median_ms(rows, k) for k in ("interp_ms", "build_ms", "trace_ms", "shade_ms",
                                              "shadow_ms")},
            "fps_raycast": fps_raycast, "fps_full": fps_full,
            "mrays_per_s": res * res / median_ms(rows, "trace_ms") / 1e3,
            "tri_tests": median_ms(rows, "tri_tests")}


def run_bench(names, res, n_frames, packets, threads, accels=("grid",)):
    with tempfile.TemporaryDirectory(prefix="frustrace-bench-") as tmp:
        paths = {n: scene_file(n, Path(tmp)) for n in names}
        rows = []
        for n in names:
            for accel in accels:      # the kd-tree's packets are always KD_PACKET^2
                for p in (packets if accel == "grid" else packets[:1]):
                    rows.append(bench_scene(paths[n], n, res, n_frames, p, threads, accel))
        return rows
