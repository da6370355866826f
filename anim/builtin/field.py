"""field (~336K triangles): 4,000 rocks tumbling and bobbing on a plain
around a rippling torus: instancing (`instances:`, one 80-triangle rock
placed 4,000 times by TRS keys) beside vertex keyframes. Each rock turns
about its own axis, one or two whole turns a period either way (slerp
reproduces a constant spin about a fixed axis exactly), and bobs on a sine (catmull-rom, keyed 24 times a
second), so the exact motion is known at any time."""
import numpy as np
from scipy.spatial.transform import Rotation

from anim.builtin.authoring import BuiltinScene, InstancedPart, KeyframedPart, Part
from anim.builtin.shapes import heightfield, icosphere
from anim.builtin.torus import TorusScene

N_ROCKS = 4000
HALF = 9.0
PERIOD = 2.0


class FieldScene(BuiltinScene):
    name = "field"
    target_triangles = 0                 # not one of the classic scenes
    description = "4,000 tumbling rocks (copies of one) around a rippling torus: instancing (~336K triangles)"
    period = PERIOD

    def build(self):
        rng = np.random.default_rng(5)
        rv, rf = icosphere(1, 1.0)
        rv = rv * (1 + 0.25 * rng.uniform(-1, 1, (len(rv), 1)))         # a lumpy rock
        self.rocks = {"pos": np.c_[rng.uniform(-HALF, HALF, N_ROCKS), np.zeros(N_ROCKS),
                                   rng.uniform(-HALF, HALF, N_ROCKS)],
                      "axis": rng.normal(size=(N_ROCKS, 3)), "spin": rng.choice([-2.0, -1.0, 1.0, 2.0], N_ROCKS) * 2 * np.pi / PERIOD,   # whole turns a period
                      "bob": rng.uniform(0.05, 0.4, N_ROCKS), "phase": rng.uniform(0, 2 * np.pi, N_ROCKS),
                      "scale": rng.uniform(0.06, 0.2, (N_ROCKS, 3))}
        self.rocks["axis"] /= np.linalg.norm(self.rocks["axis"], axis=1, keepdims=True)
        centre = np.hypot(self.rocks["pos"][:, 0], self.rocks["pos"][:, 2]) < 2.2     # clear of the torus
        self.rocks["pos"][centre] *= 2.2 / np.maximum(np.hypot(self.rocks["pos"][centre, 0],
                                                               self.rocks["pos"][centre, 2]), 1e-9)[:, None]
        torus = TorusScene()
        fv, ff, fuv = heightfield(2 * HALF + 2, 1, lambda x, z: np.zeros_like(x) - 0.3)
        self.parts = [Part("ground", fv, ff, material="ground"),
                      KeyframedPart("torus", torus.positions, torus.parts[0].faces, np.linspace(0, PERIOD, 9),
                                    material="clay"),
                      InstancedPart("rocks", rv, rf, self._motion, np.linspace(0, PERIOD, 49), material="rock")]
        self.camera = "camera: {eye: [0, 6.5, 11], look_at: [0, 0, 0], up: [0, 1, 0], fov: 50}\n"
        self.lights = ["{type: point, position: [4, 9, 6], intensity: 50}",
                       "{type: directional, direction: [-0.3, -1, -0.4], intensity: 0.5}"]
        self.materials = {"clay": "{diffuse: [0.7, 0.6, 0.5], specular: 0.2, shininess: 32}",
                          "rock": "{diffuse: [0.45, 0.42, 0.4], specular: 0.05, shininess: 8}",
                          "ground": "{diffuse: [0.35, 0.45, 0.3]}"}

    def _motion(self, t):
        """(T, R, S) of every rock at time t: a spin about its axis, a bob."""
        r = self.rocks
        tr = r["pos"] + np.c_[np.zeros(N_ROCKS), r["bob"] * (1 + np.sin(2 * np.pi * t / PERIOD + r["phase"])),
                              np.zeros(N_ROCKS)]
        rot = Rotation.from_rotvec(r["axis"] * (r["spin"] * t)[:, None]).as_matrix()
        return tr, rot, r["scale"]
