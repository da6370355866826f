"""hand (~16K triangles): a palm and five fingers on a 16-joint skeleton; the
fingers curl and open in a wave and the wrist waves. Joint angles keyed
13 times per 2 s cycle (catmull-rom, looped), linear blend skinning with two
influences per vertex blended across each knuckle."""
import numpy as np

from anim.builtin.authoring import BuiltinScene, Part, SkinnedPart, chain_weights
from anim.builtin.shapes import capsule, ellipsoid, merge
from anim.builtin.textures import checker

BLEND = 0.05        # half-width (in finger-length units) of the weight blend at a knuckle
CYCLE = 2.0


# (base, direction, length, radius, knuckles at s=, curl axis weights, curl amplitudes deg, phase)
FINGERS = [
    ((-0.33, 0.42, 0.0), (-0.08, 1, 0), 0.78, 0.085, (0.45, 0.75), (1, 0, 0), (70, 85, 60), 0.0),
    ((-0.11, 0.46, 0.0), (-0.02, 1, 0), 0.88, 0.09, (0.45, 0.75), (1, 0, 0), (70, 90, 60), 0.5),
    ((0.11, 0.46, 0.0), (0.02, 1, 0), 0.84, 0.09, (0.45, 0.75), (1, 0, 0), (70, 90, 60), 1.0),
    ((0.32, 0.40, 0.0), (0.08, 1, 0), 0.64, 0.08, (0.45, 0.75), (1, 0, 0), (70, 85, 60), 1.5),
    ((0.40, -0.12, 0.05), (0.75, 0.62, 0.25), 0.62, 0.1, (0.4, 0.72), (0.4, -0.3, 0.6), (35, 45, 40), 2.0),
]


class HandScene(BuiltinScene):
    name = "hand"
    target_triangles = 16000           # ../shared/SPEC.md section 6
    description = "palm and five articulated fingers, joint angles, skinned (~16K triangles)"
    period = CYCLE

    def build(self):
        parts, joints = [], [("wrist", -1, (0.0, -0.55, 0.0))]
        joint_idx, weights = [], []
        palm_v, palm_f = ellipsoid((0.0, 0.0, 0.0), (0.46, 0.52, 0.13), n_lat=24, n_lon=40)
        parts.append((palm_v, palm_f))
        joint_idx.append(np.zeros((len(palm_v), 2), int))
        weights.append(np.tile([1.0, 0.0], (len(palm_v), 1)))
        self.curls = []
        for f, (base, direction, length, radius, knuckles, axis, amp, phase) in enumerate(FINGERS):
            base = np.asarray(base)
            d = np.asarray(direction, float)
            d /= np.linalg.norm(d)
            tip = base + d * length
            v, fc, s = capsule(base, tip, radius, n_around=32, n_along=36, n_cap=6, radius_b=radius * 0.8)
            first = len(joints)
            stops = (0.0, *knuckles)
            for k, s_k in enumerate(stops):
                parent = 0 if k == 0 else first + k - 1
                joints.append((f"finger{f}_{k}", parent, tuple(base + d * length * s_k)))
            self.curls.append((first, np.asarray(axis, float), np.asarray(amp, float), phase))
            ji, w = chain_weights(s, stops, [first, first + 1, first + 2], 0, BLEND)
            parts.append((v, fc))
            joint_idx.append(ji)
            weights.append(w)
        verts, faces = merge(parts)
        skin = SkinnedPart("hand", verts, faces, joints, np.concatenate(joint_idx), np.concatenate(weights),
                           self.angles, np.linspace(0, CYCLE, 13), material="skin")
        floor = Part("floor", [[-3, -0.95, -2], [3, -0.95, -2], [3, -0.95, 3], [-3, -0.95, 3]],
                     [[0, 2, 1], [0, 3, 2]], material="floor", uvs=[[0, 0], [3, 0], [3, 3], [0, 3]])
        self.parts = [floor, skin]
        self.textures = {"checker.png": checker(256, 8, (0.25, 0.3, 0.35), (0.75, 0.75, 0.7))}
        self.materials = {"skin": "{diffuse: [0.86, 0.64, 0.52], specular: 0.15, shininess: 24}",
                          "floor": "{diffuse: [1, 1, 1], texture: checker.png}"}
        self.lights = ["{type: point, position: [2.5, 3, 4], intensity: 30}",
                       "{type: directional, direction: [0.4, -0.8, -0.6], intensity: 0.35}"]
        self.camera = "camera: {eye: [0.9, 0.5, 3.4], look_at: [0, 0.25, 0.1], up: [0, 1, 0], fov: 42}\n"
        self.n_joints = len(joints)

    def angles(self, t):
        """(J, 3) joint angles in degrees at time t: a curling wave across the fingers."""
        a = np.zeros((self.n_joints, 3))
        w = 2 * np.pi * t / CYCLE
        a[0] = [10 * np.sin(w), 20 * np.sin(w + 0.7), 8 * np.sin(2 * w)]
        for first, axis, amp, phase in self.curls:
            curl = 0.5 - 0.5 * np.cos(w - phase * 0.6)
            for k in range(3):
                a[first + k] = axis * amp[k] * curl
        return a
