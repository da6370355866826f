"""fairy (~174K triangles): a forest — hilly ground, conifers and broadleaf
trees, rocks, mushrooms — that never moves, and a small fairy (1.5K
triangles) flying a loop through it with flapping wings, followed by a
fly-through camera. The case for leaving static work out: the forest is
loaded, gathered and binned once (raycore/grid/incremental.py)."""
import numpy as np
from scipy.spatial.transform import Rotation

from anim.builtin.authoring import BuiltinScene, Part, RigidPart
from anim.builtin.shapes import capsule, cone, ellipsoid, heightfield, icosphere, merge
from anim.builtin.textures import grass, value_noise

LOOP = 4.0
SIZE = 30.0
CAMERA_RADIUS = 6.0


def ground_height(x, z):
    return 0.45 * np.sin(0.3 * x + 0.5) * np.cos(0.25 * z) + 0.2 * np.sin(0.7 * x + 1.0) * np.sin(0.5 * z)


class FairyScene(BuiltinScene):
    name = "fairy"
    target_triangles = 174000           # ../shared/SPEC.md section 6
    description = "a large static forest with a small flying fairy (~174K triangles)"
    period = LOOP
    frames = (0, 95, 24)

    def build(self):
        rng = np.random.default_rng(2006)
        gv, gf, guv = heightfield(SIZE, 120, ground_height, uv_repeat=6.0)
        parts = [Part("ground", gv, gf, material="grass", uvs=guv)]
        trunks, needles, leaves, stones, stems, caps = [], [], [], [], [], []
        spots = self._scatter(rng, 54 + 24 + 40, min_gap=1.1)
        for i, (x, z) in enumerate(spots[:54]):
            y = ground_height(x, z)
            h = rng.uniform(2.5, 4.5)
            trunks.append(capsule((x, y - 0.2, z), (x, y + h * 0.5, z), 0.12 * h / 3.5, 16, 8, 3)[:2])
            if i < 30:                                       # conifer: four stacked cones
                for k in range(4):
                    base = y + h * (0.25 + 0.18 * k)
                    v, f = cone((x, base, z), h * 0.35, h * (0.28 - 0.05 * k), 32, 6)
                    needles.append((v, f))
            else:                                            # broadleaf: two blobs
                for k in range(2):
                    c = (x + rng.uniform(-0.3, 0.3), y + h * (0.6 + 0.2 * k), z + rng.uniform(-0.3, 0.3))
                    leaves.append(ellipsoid(c, (h * 0.3, h * 0.22, h * 0.3), 20, 28))
        for x, z in spots[54:78]:
            v, f = icosphere(2, 1.0)
            bumps = 1 + 0.25 * (rng.random(len(v)) - 0.5)
            scale = rng.uniform(0.2, 0.6, 3)
            stones.append((v * bumps[:, None] * scale + (x, ground_height(x, z), z), f))
        for x, z in spots[78:]:
            y = ground_height(x, z)
            s = rng.uniform(0.6, 1.2)
            stems.append(capsule((x, y - 0.05, z), (x, y + 0.25 * s, z), 0.04 * s, 10, 3, 2)[:2])
            caps.append(ellipsoid((x, y + 0.27 * s, z), (0.15 * s, 0.07 * s, 0.15 * s), 8, 16))
        for name, group, mat in (("trunks", trunks, "bark"), ("conifers", needles, "needles"),
                                 ("broadleaves", leaves, "leaves"), ("rocks", stones, "rock"),
                                 ("stems", stems, "stem"), ("mushrooms", caps, "mushroom")):
            parts.append(Part(name, *merge(group), material=mat))
        # the fairy: a body and head, and two wings flapping about its forward axis
        body = merge([capsule((0, -0.12, 0), (0, 0.1, 0), 0.045, 12, 8, 4)[:2],
                      ellipsoid((0, 0.17, 0), (0.055, 0.065, 0.055), 10, 16)])
        keys = np.linspace(0, LOOP, 193)
        parts.append(RigidPart("fairy", *body, self._body_motion, keys, material="fairy"))
        for side in (1, -1):
            wing = ellipsoid((0, 0.0, side * 0.16), (0.05, 0.008, 0.15), 10, 24)
            parts.append(RigidPart(f"wing_{'l' if side > 0 else 'r'}", *wing, self._wing_motion(side), keys,
                                   material="wing"))
        self.parts = parts
        self.textures = {"grass.png": grass(),
                         "bark.png": np.repeat(0.3 + 0.4 * value_noise(128, 16, 5)[..., None], 3, -1) * (0.5, 0.36, 0.25)}
        self.materials = {"grass": "{diffuse: [1, 1, 1], texture: grass.png}",
                          "bark": "{diffuse: [0.45, 0.32, 0.22]}",
                          "needles": "{diffuse: [0.1, 0.35, 0.15], specular: 0.05}",
                          "leaves": "{diffuse: [0.3, 0.55, 0.15], specular: 0.05}",
                          "rock": "{diffuse: [0.5, 0.5, 0.48], specular: 0.1}",
                          "stem": "{diffuse: [0.9, 0.88, 0.8]}",
                          "mushroom": "{diffuse: [0.85, 0.1, 0.08], specular: 0.3}",
                          "fairy": "{diffuse: [0.95, 0.75, 0.85], specular: 0.5, shininess: 64}",
                          "wing": "{diffuse: [0.7, 0.9, 1.0], specular: 0.9, shininess: 96}"}
        self.lights = ["{type: directional, direction: [-0.4, -1, -0.3], intensity: 1.3}",
                       "{type: point, position: [0, 6, 0], intensity: 30}"]
        self.render = "render: {background: [0.55, 0.7, 0.9], ambient: 0.12}\n"
        cam = []
        for k in range(9):
            t = LOOP * k / 8
            pos = self.path(t)
            a = 2 * np.pi * t / LOOP - 0.9
            x, z = CAMERA_RADIUS * np.cos(a), CAMERA_RADIUS * np.sin(a)
            eye = (x, ground_height(x, z) + 3.0, z)
            cam.append(f"    - {{t: {t:g}, eye: [{eye[0]:.4f}, {eye[1]:.4f}, {eye[2]:.4f}], "
                       f"look_at: [{pos[0]:.4f}, {pos[1]:.4f}, {pos[2]:.4f}], fov: 40}}\n")
        self.camera = "camera:\n  interpolation: catmull-rom\n  keys:\n" + "".join(cam)

    @staticmethod
    def _scatter(rng, n, min_gap):
        """n ground positions at least min_gap apart, in the grove inside the
        fairy's flight loop or in the forest beyond the camera's circle."""
        out = []
        while len(out) < n:
            x, z = rng.uniform(-SIZE / 2 + 1, SIZE / 2 - 1, 2)
            if np.hypot(x / 4.0, z / 3.0) > 0.75 and np.hypot(x, z) < CAMERA_RADIUS + 1.0:
                continue
            if all((x - a) ** 2 + (z - b) ** 2 >= min_gap ** 2 for a, b in out):
                out.append((x, z))
        return out

    def path(self, t):
        """The fairy's position: an elliptic loop, bobbing."""
        a = 2 * np.pi * t / LOOP
        x, z = 4.0 * np.cos(a), 3.0 * np.sin(a)
        return np.array([x, ground_height(x, z) + 1.4 + 0.25 * np.sin(2 * a), z])

    def _heading(self, t):
        a = 2 * np.pi * t / LOOP
        dx, dz = -4.0 * np.sin(a), 3.0 * np.cos(a)
        return Rotation.from_euler("y", -np.degrees(np.arctan2(dz, dx)), degrees=True)

    def _body_motion(self, t):
        return self._heading(t).as_matrix(), self.path(t)

    def _wing_motion(self, side):
        def motion(t):
            flap = Rotation.from_euler("x", side * 40 * np.sin(2 * np.pi * 5 * t), degrees=True)
            heading = self._heading(t)
            return (heading * flap).as_matrix(), self.path(t) + heading.apply([0, 0.05, 0])
        return motion
