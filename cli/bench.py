"""`frustrace bench`: fps per phase on built-in scenes, medians over frames.

Frames are rendered exactly as `render` does (interpolate, rebuild, trace,
shadow, shade) and written to one temporary EXR (write_ms); compile time is
spent in a warm-up first and reported apart. Rows follow SPEC section 5, plus
interp_ms, write_ms and shadow_mrays_per_s.
"""
import tempfile
import time
from pathlib import Path

from anim.errors import SceneError
from anim import builtin
from anim.scene import AnimatedScene

from raycore.frame import KD_PACKET
from raycore.image_io import write_exr

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
                accel: str = "grid", workdir: Path = None) -> dict:
    scene = AnimatedScene(path)
    cfg = config_of(scene, width=res, height=res, packet=packet, threads=threads, aovs=(), accel=accel)
    renderer = SceneRenderer(scene, cfg, shading_of(scene))
    frames = scene.frame_numbers[:max(1, n_frames)]
    rows = []
    for i, frame in enumerate([frames[0]] + frames):       # first pass = warm-up
        interp_ms, result = renderer.render(scene.time_of(frame))
        t0 = time.perf_counter()
        if workdir is not None:          # the frame's EXR, as `render` writes it
            write_exr(str(workdir / "bench_frame.exr"), {"RGBA": result.rgba, "Z": result.z}, {},
                      scene.spec.output.compression)
        write_ms = (time.perf_counter() - t0) * 1e3
        if i > 0:
            rows.append({"interp_ms": interp_ms, **result.timings, "write_ms": write_ms,
                         "tri_tests": result.counters["tri_tests"],
                         "shadow_rays": result.counters["shadow_rays"]})
    fps_raycast, fps_full = fps_of(rows)
    return {"scene": name, "accel": accel, "packet": packet if accel == "grid" else KD_PACKET, "threads": threads,
            "triangles": int(scene.faces.shape[0]), "resolution": res, "frames": len(rows),
            **{k: median_ms(rows, k) for k in ("interp_ms", "build_ms", "trace_ms", "shade_ms",
                                              "shadow_ms", "write_ms")},
            "fps_raycast": fps_raycast, "fps_full": fps_full,
            "mrays_per_s": res * res / median_ms(rows, "trace_ms") / 1e3,
            # shadow rays actually cast (facing-away points and dark lights cost none)
            "shadow_mrays_per_s": (median_ms(rows, "shadow_rays") / median_ms(rows, "shadow_ms") / 1e3
                                   if median_ms(rows, "shadow_ms") > 0 else 0.0),
            "tri_tests": median_ms(rows, "tri_tests")}


def run_bench(names, res, n_frames, packets, threads, accels=("grid",)):
    with tempfile.TemporaryDirectory(prefix="frustrace-bench-") as tmp:
        paths = {n: scene_file(n, Path(tmp)) for n in names}
        rows = []
        for n in names:
            for accel in accels:      # the kd-tree's packets are always KD_PACKET^2
                for p in (packets if accel == "grid" else packets[:1]):
                    rows.append(bench_scene(paths[n], n, res, n_frames, p, threads, accel, Path(tmp)))
        return rows


PHASES = ("interp", "build", "trace", "shade", "shadow", "write")


def plot_phases(rows, path: Path):
    """Stacked bars of median ms per phase, one bar per scene and setting."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    labels = [f"{r['scene']}\n{r['accel']} {r['packet']}" for r in rows]
    fig, ax = plt.subplots(figsize=(max(6, 1.1 * len(rows)), 4.5))
    bottom = [0.0] * len(rows)
    for phase in PHASES:
        vals = [r.get(f"{phase}_ms", 0.0) for r in rows]
        ax.bar(labels, vals, bottom=bottom, label=phase)
        bottom = [b + v for b, v in zip(bottom, vals)]
    ax.set_ylabel("ms per frame (median)")
    res = rows[0]["resolution"] if rows else 0
    ax.set_title(f"frustrace bench: {res}x{res}, {rows[0]['threads'] if rows else 0} threads")
    ax.legend(ncol=len(PHASES), fontsize=8, loc="upper left")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
