"""torus (16,384 triangles): a torus whose cross-section ripples, vertex
keyframes with catmull-rom, the deforming-mesh benchmark of the foundation."""
import numpy as np

from anim.builtin.authoring import BuiltinScene, KeyframedPart


class TorusScene(BuiltinScene):
    name = "torus"
    target_triangles = 0               # not one of the classic scenes
    description = "a rippling torus: vertex keyframes (16K triangles)"
    period = 2.0                          # the ripple's phase turns once in 2 s

    def build(self, nu=128, nv=64):
        u = np.linspace(0, 2 * np.pi, nu, endpoint=False)
        w = np.linspace(0, 2 * np.pi, nv, endpoint=False)
        self._u, self._w = (a.reshape(-1) for a in np.meshgrid(u, w, indexing="ij"))
        i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
        a, b = i * nv + j, ((i + 1) % nu) * nv + j
        c, d = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
        faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
        self.parts = [KeyframedPart("torus", self.positions, faces, np.linspace(0, self.period, 9),
                                    material="clay")]
        self.camera = "camera: {eye: [0, 2.6, 2.9], look_at: [0, 0.4, 0], up: [0, 1, 0], fov: 45}\n"
        self.lights = ["{type: point, position: [2, 4, 3], intensity: 25}"]
        self.materials = {"clay": "{diffuse: [0.7, 0.6, 0.5], specular: 0.2, shininess: 32}"}

    def positions(self, t):
        """(n_v, 3) float64 vertex positions at time t (seconds)."""
        U, W = self._u, self._w
        r = 0.35 * (1 + 0.2 * np.sin(3 * U + 2 * np.pi * t / self.period))
        return np.stack([(1 + r * np.cos(W)) * np.cos(U), r * np.sin(W) + 0.5, (1 + r * np.cos(W)) * np.sin(U)], -1)
