"""`frustrace bench --instances`: frame cost by phase and memory of an
instanced world, from a thousand to a hundred thousand copies of one
10,000-triangle prototype (a torus; a hundred thousand copies are a billion
triangles flattened), traced two-level (raycore/instancing), with the same
world flattened beside it where it fits.

The copies stand on a square field, each turned about its own axis and
rising over the frames; the camera looks across the field from above its
near edge, so the far copies crowd the horizon (every packet meets many
of them). Each count runs in a process of its own (bench --scale's
children, anim/measure/scale.py), so that its peak memory is its own; the
bytes an instance costs are the slope of peak memory between the two
largest counts (after a throwaway run, so that no count pays the kernels'
compilation).
"""
from pathlib import Path

import numpy as np

from anim.measure.scale import PHASES, _child, growth

PROTOTYPE = 10_000          # triangles of the prototype
FLAT_LIMIT = 20_000_000     # flattened triangles measured beside the two-level frames, at most


def prototype_torus():
    """(vertices, faces) of a 10,000-triangle torus (100 x 50 quads)."""
    nu, nv = 100, 50
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, nu, endpoint=False), np.linspace(0, 2 * np.pi, nv, endpoint=False),
                       indexing="ij")
    big, small = 0.35, 0.12
    points = np.stack([(big + small * np.cos(v)) * np.cos(u), small * np.sin(v),
                       (big + small * np.cos(v)) * np.sin(u)], -1).reshape(-1, 3)
    idx = np.arange(nu * nv).reshape(nu, nv)
    a, b = idx, np.roll(idx, -1, 0)
    c, d = np.roll(b, -1, 1), np.roll(idx, -1, 1)
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return points, faces


def write_scene(folder: Path, n_instances: int, res: int, instancing: str) -> Path:
    """anim.yaml of n copies (side x side) of the torus over a ground, one light."""
    folder.mkdir(parents=True, exist_ok=True)
    points, faces = prototype_torus()
    with open(folder / "torus.obj", "w") as f:
        f.write("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in points))
        f.write("".join(f"f {i + 1} {j + 1} {k + 1}\n" for i, j, k in faces))
    side = int(np.ceil(np.sqrt(n_instances)))
    rng = np.random.default_rng(0)
    gx, gz = np.meshgrid(np.arange(side), np.arange(side))
    pos = np.c_[gx.ravel() - side / 2, np.zeros(side * side), gz.ravel() - side / 2][:n_instances]
    pos[:, [0, 2]] += rng.uniform(-0.2, 0.2, (n_instances, 2))
    axis = rng.normal(size=(n_instances, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = rng.uniform(0, np.pi, n_instances)
    quats = [np.c_[np.cos(a / 2), axis * np.sin(a / 2)[:, None]] for a in (angle, angle + 0.5)]
    np.savez(folder / "copies.npz", t=np.array([0.0, 1.0]), translation=np.stack([pos, pos + [0, 0.3, 0]]),
             rotation=np.stack(quats))
    (folder / "ground.obj").write_text(f"v {-side} -0.5 {-side}\nv {side} -0.5 {-side}\nv {side} -0.5 {side}\n"
                                       f"v {-side} -0.5 {side}\nf 1 3 2\nf 1 4 3\n")
    (folder / "anim.yaml").write_text(f"""version: 1
frames: {{start: 0, end: 24, fps: 24}}
output: {{path: out/f_####.exr, resolution: [{res}, {res}]}}
render: {{instancing: {instancing}, accel: bvh}}
camera: {{eye: [0, 25, {side / 2 + 20}], look_at: [0, 0, 0], up: [0, 1, 0], fov: 60}}
lights: [{{type: point, position: [10, 80, 40], intensity: 8000}}]
materials: {{clay: {{diffuse: [0.7, 0.6, 0.5], specular: 0.2, shininess: 32}}}}
objects:
  - name: ground
    mesh: ground.obj
  - name: tori
    material: clay
    mesh: torus.obj
    instances: {{file: copies.npz}}
""")
    return folder / "anim.yaml"


def run_instances(counts, res, n_frames, threads, workdir: Path, on_count=None) -> dict:
    """{'rows': [...per count...], 'growth': {phase: exponent}, 'bytes_per_instance'}: each count
    two-level and, where it fits in FLAT_LIMIT triangles, flattened, each in a process of its own."""
    rows = []
    # a throwaway run first: a cold kernel cache's compile would swell the first count's peak memory
    _child(["frustrace", str(write_scene(workdir / "warm", min(counts), 64, "two_level")), "1", str(threads), ""])
    for n in counts:
        row = _child(["frustrace", str(write_scene(workdir / f"two_{n}", n, res, "two_level")), str(n_frames),
                      str(threads), ""])
        row["instances"] = n
        if n * PROTOTYPE <= FLAT_LIMIT:
            row["flat"] = _child(["frustrace", str(write_scene(workdir / f"flat_{n}", n, res, "flatten")),
                                  str(n_frames), str(threads), ""])
        rows.append(row)
        if on_count is not None:
            on_count(row)
    out = {"rows": rows, "growth": {k: growth([{**r, "triangles": r["instances"]} for r in rows], k)
                                    for k in (*PHASES, "frame_ms")}}
    if len(rows) >= 2:
        a, b = rows[-2], rows[-1]
        out["bytes_per_instance"] = (b["peak_rss_gb"] - a["peak_rss_gb"]) * 1024 ** 3 / (b["instances"] - a["instances"])
    return out
