"""marbles (~8.8K triangles): 110 marbles bouncing elastically in a box under
gravity, each also sliding between the walls and spinning: rigid motion,
many small objects, and a velocity jump at every bounce (the stiff case of
interpolation). Keyed 24 times per second, translation with pchip (keys
never go below the floor and pchip never overshoots them), rotation slerp.
Marbles do not collide with each other: that keeps every path analytic
(exact ground truth at any time)."""
import numpy as np
from scipy.spatial.transform import Rotation

from anim.builtin.authoring import BuiltinScene, Part, RigidPart
from anim.builtin.shapes import box, heightfield, icosphere
from anim.builtin.textures import checker

N_MARBLES = 110
RADIUS = 0.07
HALF = 1.0              # the box's inner half-width
G = 9.81
DURATION = 2.0
COLORS = ["red", "blue", "green", "amber", "white"]


def fold(u, lo, hi):
    """Position of a point moving at unit speed along u, reflected between lo and hi."""
    span = hi - lo
    p = np.mod(u - lo, 2 * span)
    return lo + np.where(p < span, p, 2 * span - p)


class MarblesScene(BuiltinScene):
    name = "marbles"
    target_triangles = 8800           # ../shared/SPEC.md section 6
    description = "110 marbles bouncing in a box: many small rigid objects (~8.8K triangles)"
    period = DURATION
    frames = (0, 47, 24)

    def build(self):
        rng = np.random.default_rng(11)
        mv, mf = icosphere(1, RADIUS)
        self.params = []
        parts = []
        fv, ff, fuv = heightfield(2 * HALF + 0.2, 1, lambda x, z: np.zeros_like(x), uv_repeat=2.0)
        parts.append(Part("floor", fv, ff, material="wood", uvs=fuv))
        wall = 0.05
        walls = [box((-HALF - wall, 0, -HALF - wall), (HALF + wall, 0.25, -HALF)),
                 box((-HALF - wall, 0, HALF), (HALF + wall, 0.25, HALF + wall)),
                 box((-HALF - wall, 0, -HALF), (-HALF, 0.25, HALF)),
                 box((HALF, 0, -HALF), (HALF + wall, 0.25, HALF))]
        for k, (v, f) in enumerate(walls):
            parts.append(Part(f"wall{k}", v, f, material="wall"))
        for i in range(N_MARBLES):
            height = rng.uniform(0.3, 1.3)
            p = {"x0": rng.uniform(-HALF, HALF), "z0": rng.uniform(-HALF, HALF),
                 "vx": rng.uniform(-0.8, 0.8), "vz": rng.uniform(-0.8, 0.8),
                 "v0": np.sqrt(2 * G * height), "phase": rng.uniform(0, 1),
                 "axis": rng.normal(size=3), "spin": rng.uniform(2, 8)}
            p["axis"] /= np.linalg.norm(p["axis"])
            self.params.append(p)
            parts.append(RigidPart(f"marble{i:03d}", mv, mf, self._motion(p), np.linspace(0, DURATION, 49),
                                   material=COLORS[i % len(COLORS)], interpolation="pchip",
                                   extrapolate="clamp", mesh_file="marble.obj"))
        self.parts = parts
        self.textures = {"wood.png": checker(256, 8, (0.45, 0.3, 0.18), (0.55, 0.38, 0.22))}
        self.materials = {"wood": "{diffuse: [1, 1, 1], texture: wood.png}",
                          "wall": "{diffuse: [0.6, 0.6, 0.65]}",
                          "red": "{diffuse: [0.8, 0.1, 0.1], specular: 0.8, shininess: 96}",
                          "blue": "{diffuse: [0.1, 0.25, 0.85], specular: 0.8, shininess: 96}",
                          "green": "{diffuse: [0.1, 0.7, 0.25], specular: 0.8, shininess: 96}",
                          "amber": "{diffuse: [0.9, 0.6, 0.1], specular: 0.8, shininess: 96}",
                          "white": "{diffuse: [0.9, 0.9, 0.88], specular: 0.8, shininess: 96}"}
        self.lights = ["{type: point, position: [1, 4, 2], intensity: 25}",
                       "{type: directional, direction: [0.3, -1, -0.5], intensity: 0.4}"]
        self.camera = "camera: {eye: [0, 2.9, 3.0], look_at: [0, 0.25, 0], fov: 45}\n"

    def _motion(self, p):
        lo, hi = -HALF + RADIUS, HALF - RADIUS
        flight = 2 * p["v0"] / G

        def motion(t):
            tau = np.mod(t + p["phase"] * flight, flight)
            y = RADIUS + p["v0"] * tau - 0.5 * G * tau * tau
            x = fold(p["x0"] + p["vx"] * t, lo, hi)
            z = fold(p["z0"] + p["vz"] * t, lo, hi)
            return Rotation.from_rotvec(p["axis"] * p["spin"] * t).as_matrix(), np.array([x, y, z])
        return motion
