"""`frustrace bench --scale`: frame cost by phase and peak memory from
thousands to millions of triangles, on a generated deforming mesh (the
built-in torus's rippling motion at any resolution, written as binary PLY
vertex keyframes), with Embree beside it where embreex is installed, and
each phase's growth exponent (the slope of log ms against log triangles).

Every size runs in a process of its own, so that its peak resident memory
(the kernel's high-water mark, VmHWM) is its own; the keyframes' own bytes
are reported apart from what frustrace adds to them.
"""
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from anim.memory import status_bytes

PHASES = ("interp_ms", "build_ms", "trace_ms", "shade_ms", "shadow_ms")
KEYS = 3                                   # vertex keyframes at t = 0, 0.5, 1 s
PERIOD = 2.0


def torus(n_triangles, t):
    """(vertices (n_v, 3) f32, faces (n_t, 3) i32) of the rippling torus with
    about n_triangles triangles (nu x nv quads, nv = nu / 2) at time t."""
    nu = max(8, int(round(np.sqrt(n_triangles))))
    nv = max(4, nu // 2)
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    w = np.linspace(0, 2 * np.pi, nv, endpoint=False)
    U, W = (a.reshape(-1) for a in np.meshgrid(u, w, indexing="ij"))
    r = 0.35 * (1 + 0.2 * np.sin(3 * U + 2 * np.pi * t / PERIOD))
    verts = np.stack([(1 + r * np.cos(W)) * np.cos(U), r * np.sin(W) + 0.5, (1 + r * np.cos(W)) * np.sin(U)], -1)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = i * nv + j, ((i + 1) % nu) * nv + j
    c, d = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return verts.astype(np.float32), faces.astype(np.int32)


def write_ply(path, vertices, faces):
    """A binary little-endian PLY of float32 vertices and triangle faces."""
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\nproperty float x\n"
            f"property float y\nproperty float z\nelement face {len(faces)}\n"
            "property list uchar int vertex_indices\nend_header\n").encode()
    rows = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    rows["n"], rows["v"] = 3, faces
    with open(path, "wb") as f:
        f.write(head)
        f.write(np.ascontiguousarray(vertices, "<f4").tobytes())
        f.write(rows.tobytes())


def write_scene(folder: Path, n_triangles: int, res: int) -> Path:
    """anim.yaml of the torus at this size: KEYS PLY keyframes, one light."""
    folder.mkdir(parents=True, exist_ok=True)
    keys = []
    for k in range(KEYS):
        t = k * 0.5
        verts, faces = torus(n_triangles, t)
        write_ply(folder / f"key_{k}.ply", verts, faces)
        keys.append(f"      - {{t: {t}, mesh: key_{k}.ply}}\n")
    (folder / "anim.yaml").write_text(f"""version: 1
frames: {{start: 0, end: 24, fps: 24}}
output: {{path: out/f_####.exr, resolution: [{res}, {res}]}}
camera: {{eye: [0, 2.6, 2.9], look_at: [0, 0.4, 0], up: [0, 1, 0], fov: 45}}
lights: [{{type: point, position: [2, 4, 3], intensity: 25}}]
materials: {{clay: {{diffuse: [0.7, 0.6, 0.5], specular: 0.2, shininess: 32}}}}
objects:
  - name: torus
    material: clay
    interpolation: linear
    keyframes:
{''.join(keys)}""")
    return folder / "anim.yaml"


def measure_frustrace(path, n_frames, threads, accel):
    """One size in this process: medians per phase over n_frames frames after
    the warm-up, frame 0's build, the warm-up's seconds, peak RSS."""
    from anim.render.renderer import SceneRenderer
    from anim.render.settings import config_of, shading_of
    from anim.render.stats import median_ms
    from anim.render.warm_up import warm_up
    from anim.scene import AnimatedScene
    from raycore.jit.presets import set_threads
    set_threads(threads)
    base = status_bytes("VmRSS")                # the interpreter, numba, the libraries
    scene = AnimatedScene(path)
    # the keyframes as stored (float32 positions), the floor a renderer of them cannot go below
    keyframe_bytes = scene.key_bytes
    cfg = config_of(scene, threads=threads, **({"accel": accel} if accel else {}))
    shading = shading_of(scene)
    renderer = SceneRenderer(scene, cfg, shading)
    t0 = time.perf_counter()
    warm_up(scene, shading, cfg, scene.time_of(0), structures=renderer.structures)
    warm_s = time.perf_counter() - t0
    rows = []
    for frame in range(1, n_frames + 1):
        interp_ms, result = renderer.render(scene.time_of(frame))
        rows.append({"interp_ms": interp_ms, **result.timings})
    n = int(scene.flat_triangles)           # an instanced world's: every copy's
    peak = status_bytes("VmHWM")
    return {"triangles": n, "instances": int(len(scene.instance_proto)), **{k: median_ms(rows, k) for k in PHASES},
            "frame_ms": median_ms(rows, *PHASES), "warm_up_s": warm_s, "accel": cfg.accel,
            "peak_rss_gb": peak / 1024 ** 3, "base_rss_gb": base / 1024 ** 3, "keyframe_bytes": keyframe_bytes,
            "bytes_per_triangle": (peak - base - keyframe_bytes) / max(n, 1)}


def measure_embree(path, n_frames, threads):
    """Embree (embreex) on the same frames: rebuilt every frame, camera rays
    and one shadow ray per hit, medians; None when embreex is not installed."""
    from anim.measure.peers import Embreex, peer_frame
    from anim.render.settings import shading_of
    from anim.scene import AnimatedScene
    from raycore.frame import CameraPose
    try:
        peer = Embreex(threads)
    except Exception:
        return None
    scene = AnimatedScene(path)
    lights = shading_of(scene).lights
    res = scene.spec.output.resolution[0]
    rows = []
    for frame in range(0, n_frames + 1):                 # frame 0: warm-up
        t = scene.time_of(frame)
        timings, _ = peer_frame(peer, scene.vertices_at(t), scene.faces, CameraPose(*scene.camera_at(t)),
                                res, res, lights)
        if frame:
            rows.append(timings)
    return {k: float(np.median([r[k] for r in rows])) for k in ("build_ms", "trace_ms", "shadow_ms")}


def growth(rows, key):
    """The exponent p of ms ~ triangles^p from the smallest to the largest size."""
    a, b = rows[0], rows[-1]
    if a[key] <= 0 or b[key] <= 0 or b["triangles"] == a["triangles"]:
        return None
    return float(np.log(b[key] / a[key]) / np.log(b["triangles"] / a["triangles"]))


def run_scale(sizes, res, n_frames, threads, workdir: Path, accel=None, peers=True, on_size=None) -> dict:
    """{'rows': [...per size...], 'growth': {phase: exponent}}: each size in a
    process of its own (its peak memory), Embree beside it in another."""
    rows = []
    for n in sizes:
        path = write_scene(workdir / f"torus_{n}", int(n), res)
        row = _child(["frustrace", str(path), str(n_frames), str(threads), accel or ""])
        if peers:
            row["embree"] = _child(["embree", str(path), str(n_frames), str(threads)])
        rows.append(row)
        if on_size is not None:
            on_size(row)
    keys = [*PHASES, "frame_ms"]
    out = {"rows": rows, "growth": {k: growth(rows, k) for k in keys}}
    with_embree = [r for r in rows if r.get("embree")]
    if len(with_embree) >= 2:
        out["embree_growth"] = {k: growth([{**r["embree"], "triangles": r["triangles"]} for r in with_embree], k)
                                for k in ("build_ms", "trace_ms", "shadow_ms")}
    return out


def _child(args):
    """The JSON a `python -m anim.measure.scale` child prints (one size)."""
    out = subprocess.run([sys.executable, "-m", "anim.measure.scale", *args], capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"bench --scale: the {args[0]} run of {args[1]} failed: {out.stderr.strip()[-400:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    kind, scene_path, frames, n_threads = sys.argv[1:5]
    if kind == "frustrace":
        result = measure_frustrace(scene_path, int(frames), int(n_threads), sys.argv[5] or None)
    else:
        result = measure_embree(scene_path, int(frames), int(n_threads))
    print(json.dumps(result))
