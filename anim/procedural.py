"""Procedural scenes generated on demand (nothing large is committed)."""
from pathlib import Path

import numpy as np


def write_obj(path, vertices, faces):
    """Plain OBJ (positions and triangles; 1-based indices)."""
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    Path(path).write_text("\n".join(lines) + "\n")


class TorusScene:
    """A 16,384-triangle torus whose cross-section ripples (vertex keyframes
    with catmull-rom), 1024^2, one point light: the deforming-mesh benchmark
    of the foundation issue. Its exact motion is `exact(t)`."""
    name = "torus"
    period = 2.0                          # the ripple's phase turns once in 2 s

    def __init__(self, nu=128, nv=64):
        u = np.linspace(0, 2 * np.pi, nu, endpoint=False)
        w = np.linspace(0, 2 * np.pi, nv, endpoint=False)
        self._u, self._w = (a.reshape(-1) for a in np.meshgrid(u, w, indexing="ij"))
        i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
        a, b = i * nv + j, ((i + 1) % nu) * nv + j
        c, d = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
        self.faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                                     np.stack([a, c, d], -1).reshape(-1, 3)])

    def exact(self, t):
        """(n_v, 3) float64 vertex positions at time t (seconds)."""
        U, W = self._u, self._w
        r = 0.35 * (1 + 0.2 * np.sin(3 * U + 2 * np.pi * t / self.period))
        return np.stack([(1 + r * np.cos(W)) * np.cos(U), r * np.sin(W) + 0.5, (1 + r * np.cos(W)) * np.sin(U)], -1)

    def write(self, out_dir, n_keys=9):
        """DIR/anim.yaml and its OBJ keyframes (one period, looped)."""
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        keys = []
        for k in range(n_keys):
            t = k * self.period / (n_keys - 1)
            write_obj(out_dir / f"torus_{k:03d}.obj", self.exact(t), self.faces)
            keys.append(f"      - {{t: {t:.4f}, mesh: torus_{k:03d}.obj}}")
        (out_dir / "anim.yaml").write_text("""version: 1
frames: {start: 0, end: 47, fps: 24}
output: {path: out/frame_####.exr, resolution: [1024, 1024]}
camera: {eye: [0, 2.6, 2.9], look_at: [0, 0.4, 0], up: [0, 1, 0], fov: 45}
render: {shadows: true}
lights:
  - {type: point, position: [2, 4, 3], intensity: 25}
materials:
  clay: {diffuse: [0.7, 0.6, 0.5], specular: 0.2, shininess: 32}
objects:
  - name: torus
    material: clay
    interpolation: catmull-rom
    extrapolate: loop
    keyframes:
""" + "\n".join(keys) + "\n")


SCENES = {"torus": TorusScene()}
