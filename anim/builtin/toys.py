"""toys (~11K triangles): rigid toys on TRS tracks — a precessing spinning
top, a bouncing striped ball, a car driving in a circle with rolling wheels,
a rocking duck — and one deforming object, a wobbling jelly (vertex
keyframes). Tracks keyed 12 times per second."""
import numpy as np
from scipy.spatial.transform import Rotation

from anim.builtin.authoring import BuiltinScene, KeyframedPart, Part, RigidPart
from anim.builtin.shapes import capsule, cone, ellipsoid, heightfield, icosphere, merge
from anim.builtin.textures import checker, stripes

LOOP = 4.0                       # every motion repeats after 4 s
KEYS = np.linspace(0, LOOP, 49)
WHEEL_TURNS = 8                  # ~ the car's path length / the wheel's circumference


def _rz(deg):
    return Rotation.from_euler("z", deg, degrees=True)


class ToysScene(BuiltinScene):
    name = "toys"
    target_triangles = 11000           # ../shared/SPEC.md section 6
    description = "rigid toys on TRS tracks plus a wobbling jelly (~11K triangles)"
    period = LOOP
    frames = (0, 95, 24)

    def build(self):
        parts = []
        fv, ff, fuv = heightfield(6.0, 2, lambda x, z: np.zeros_like(x), uv_repeat=3.0)
        parts.append(Part("floor", fv, ff, material="floor", uvs=fuv))
        # spinning top: cone body (tip down at the origin) and a handle
        body = cone((0, 0.0, 0), -0.35, 0.28, n_around=48, n_rings=8)
        body = (body[0] + [0, 0.35, 0], body[1])
        handle = capsule((0, 0.34, 0), (0, 0.55, 0), 0.04, 16, 6, 3)[:2]
        disk = ellipsoid((0, 0.35, 0), (0.3, 0.03, 0.3), 6, 40)
        tv, tf = merge([body, handle, disk])
        parts.append(RigidPart("top", tv, tf, self.top_motion, KEYS, material="red", rotation="spline"))
        # bouncing ball with stripes (UVs from the sphere's latitude)
        bv, bf = icosphere(3, 0.22)
        buv = np.stack([np.arctan2(bv[:, 2], bv[:, 0]) / (2 * np.pi) + 0.5, 0.5 + bv[:, 1] / 0.44], -1)
        parts.append(RigidPart("ball", bv, bf, self.ball_motion, KEYS, material="ball", uvs=buv,
                               interpolation="pchip"))
        # car: body and four wheels, each wheel its own rigid part
        car = merge([ellipsoid((0, 0.22, 0), (0.36, 0.12, 0.18), 12, 28), ellipsoid((-0.05, 0.34, 0), (0.17, 0.1, 0.14), 12, 24)])
        parts.append(RigidPart("car", *car, self.car_motion, KEYS, material="blue"))
        wheel = capsule((0, 0, -0.035), (0, 0, 0.035), 0.09, 16, 2, 3)[:2]
        for k, (wx, wz) in enumerate([(0.22, 0.17), (0.22, -0.17), (-0.22, 0.17), (-0.22, -0.17)]):
            parts.append(RigidPart(f"wheel{k}", *wheel, self._wheel_motion((wx, wz)), KEYS,
                                   material="dark", mesh_file="wheel.obj"))
        # rocking duck
        duck = merge([ellipsoid((0, 0.16, 0), (0.22, 0.13, 0.15), 12, 28), ellipsoid((0.14, 0.33, 0), (0.09, 0.09, 0.09), 10, 20),
                      capsule((0.2, 0.33, 0), (0.29, 0.32, 0), 0.03, 12, 2, 3)[:2]])
        parts.append(RigidPart("duck", *duck, self.duck_motion, KEYS, material="yellow"))
        # jelly: a sphere squashing and wobbling (vertex keyframes)
        jv, jf = icosphere(4, 0.3)
        self._jelly = jv
        parts.append(KeyframedPart("jelly", self.jelly_positions, jf, KEYS, material="green"))
        self.parts = parts
        self.textures = {"floor.png": checker(256, 6, (0.6, 0.5, 0.38), (0.75, 0.65, 0.5)),
                         "ball.png": stripes()}
        self.materials = {"floor": "{diffuse: [1, 1, 1], texture: floor.png}",
                          "red": "{diffuse: [0.85, 0.15, 0.1], specular: 0.4, shininess: 48}",
                          "ball": "{diffuse: [1, 1, 1], specular: 0.3, shininess: 40, texture: ball.png}",
                          "blue": "{diffuse: [0.15, 0.3, 0.85], specular: 0.5, shininess: 64}",
                          "dark": "{diffuse: [0.08, 0.08, 0.08], specular: 0.1}",
                          "yellow": "{diffuse: [0.95, 0.8, 0.1], specular: 0.2}",
                          "green": "{diffuse: [0.2, 0.8, 0.3], specular: 0.6, shininess: 80}"}
        self.lights = ["{type: point, position: [2, 4, 3], intensity: 30}",
                       "{type: point, position: [-3, 3, -1], intensity: 10}"]
        self.camera = "camera: {eye: [0, 2.6, 4.0], look_at: [0, 0.15, 0.2], fov: 48}\n"

    def top_motion(self, t):
        """Spins 3 turns/s about its axis, tilted 12 deg, precessing once per loop."""
        w = 2 * np.pi * t / LOOP
        spin = Rotation.from_euler("y", 360 * 3 * t, degrees=True)
        tilt = Rotation.from_euler("y", np.degrees(w), degrees=True) * Rotation.from_euler("z", 12, degrees=True)
        return (tilt * spin).as_matrix(), np.array([-0.9 + 0.3 * np.cos(w), 0.0, -0.6 + 0.3 * np.sin(w)])

    def ball_motion(self, t):
        """Two elastic bounces per second, rolling across and back."""
        s = (2 * t) % 1.0
        y = 0.22 + 1.6 * s * (1 - s) * 1.2
        x = 1.0 + 0.35 * np.sin(2 * np.pi * t / LOOP)
        return _rz(-np.degrees(0.35 * np.sin(2 * np.pi * t / LOOP) / 0.22)).as_matrix(), np.array([x, y, -0.5])

    def _car_frame(self, t):
        a = 2 * np.pi * t / LOOP
        pos = np.array([0.9 * np.cos(a), 0.0, 0.8 + 0.45 * np.sin(a)])
        yaw = Rotation.from_euler("y", -np.degrees(a) - 180, degrees=True)
        return yaw, pos

    def car_motion(self, t):
        yaw, pos = self._car_frame(t)
        return yaw.as_matrix(), pos

    def _wheel_motion(self, offset):
        wx, wz = offset

        def motion(t):
            yaw, pos = self._car_frame(t)
            roll = _rz(-360 * WHEEL_TURNS * t / LOOP)     # whole turns per loop: periodic
            return (yaw * roll).as_matrix(), pos + yaw.apply([wx, 0.09, wz])
        return motion

    def duck_motion(self, t):
        w = 2 * np.pi * t / LOOP
        rock = Rotation.from_euler("x", 15 * np.sin(4 * w), degrees=True)
        turn = Rotation.from_euler("y", 30 * np.sin(w), degrees=True)
        return (turn * rock).as_matrix(), np.array([-1.1, 0.0, 0.6])

    def jelly_positions(self, t):
        """Volume-preserving squash and stretch plus a travelling wobble."""
        v = self._jelly
        w = 2 * np.pi * t / LOOP
        sy = 1 + 0.25 * np.sin(4 * w)
        xz = 1 / np.sqrt(sy)
        ang = np.arctan2(v[:, 2], v[:, 0])
        wobble = 1 + 0.08 * np.sin(3 * ang + 2 * w) * (v[:, 1] / 0.3 + 1) / 2
        out = np.stack([v[:, 0] * xz * wobble, (v[:, 1] + 0.3) * sy, v[:, 2] * xz * wobble], -1)
        return out + [0.3, 0.0, 0.2]
