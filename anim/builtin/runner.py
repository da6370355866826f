"""runner (~78K triangles): a figure on a 13-joint skeleton running in place
(a 0.8 s stride: hips, knees, ankles, arm swing, spine twist, pelvis bob),
skinned over the whole body; the camera circles it. Joint angles keyed 17
times per stride (catmull-rom, looped)."""
import numpy as np

from anim.builtin.authoring import BuiltinScene, Part, SkinnedPart, chain_weights
from anim.builtin.shapes import capsule, ellipsoid, heightfield, merge
from anim.builtin.textures import checker

STRIDE = 0.8
BLEND = 0.06

# name, parent, origin (the figure faces +x; +z is its left)
JOINTS = [("pelvis", -1, (0, 1.0, 0)), ("spine", 0, (0, 1.22, 0)), ("neck", 1, (0, 1.52, 0)),
          ("shoulder_l", 1, (0, 1.45, 0.21)), ("elbow_l", 3, (0, 1.17, 0.22)),
          ("shoulder_r", 1, (0, 1.45, -0.21)), ("elbow_r", 5, (0, 1.17, -0.22)),
          ("hip_l", 0, (0, 0.97, 0.1)), ("knee_l", 7, (0, 0.53, 0.1)), ("ankle_l", 8, (0, 0.1, 0.1)),
          ("hip_r", 0, (0, 0.97, -0.1)), ("knee_r", 10, (0, 0.53, -0.1)), ("ankle_r", 11, (0, 0.1, -0.1))]


class RunnerScene(BuiltinScene):
    name = "runner"
    target_triangles = 78000           # ../shared/SPEC.md section 6
    description = "a running figure: skeleton, whole-body skinned deformation (~78K triangles)"
    period = STRIDE

    def build(self):
        origin = {n: np.asarray(o, float) for n, _, o in JOINTS}
        index = {n: i for i, (n, _, _) in enumerate(JOINTS)}
        parts, ji, ww = [], [], []

        def limb(mesh, stops, joints, parent):
            v, f, s = mesh
            j, w = chain_weights(s, stops, [index[n] for n in joints], index[parent], BLEND)
            parts.append((v, f))
            ji.append(j)
            ww.append(w)

        # torso: pelvis -> spine at the waist
        waist = (1.22 - 0.92) / (1.5 - 0.92)
        limb(capsule((0, 0.92, 0), (0, 1.5, 0), 0.15, 64, 96, 16, radius_b=0.17), (0, waist), ["pelvis", "spine"], "pelvis")
        limb(capsule((0, 1.47, 0), (0, 1.63, 0), 0.05, 24, 8, 4), (0, 0.3), ["spine", "neck"], "spine")
        hv, hf = ellipsoid((0.01, 1.73, 0), (0.11, 0.13, 0.1), n_lat=72, n_lon=96)
        parts.append((hv, hf))
        ji.append(np.tile([index["neck"], 0], (len(hv), 1)))
        ww.append(np.tile([1.0, 0.0], (len(hv), 1)))
        for side, sz in (("l", 1), ("r", -1)):
            sh, el = origin[f"shoulder_{side}"], origin[f"elbow_{side}"]
            hand = np.array([0.0, 0.86, 0.23 * sz])
            limb(capsule(sh, hand, 0.055, 40, 96, 10, radius_b=0.042),
                 (0, np.linalg.norm(el - sh) / np.linalg.norm(hand - sh)),
                 [f"shoulder_{side}", f"elbow_{side}"], "spine")
            hip, knee, ankle = origin[f"hip_{side}"], origin[f"knee_{side}"], origin[f"ankle_{side}"]
            limb(capsule(hip, ankle, 0.085, 48, 96, 12, radius_b=0.055),
                 (0, np.linalg.norm(knee - hip) / np.linalg.norm(ankle - hip)),
                 [f"hip_{side}", f"knee_{side}"], "pelvis")
            fv, ff, _ = capsule((-0.04, 0.06, 0.1 * sz), (0.2, 0.045, 0.1 * sz), 0.045, 32, 24, 8)
            parts.append((fv, ff))
            ji.append(np.tile([index[f"ankle_{side}"], 0], (len(fv), 1)))
            ww.append(np.tile([1.0, 0.0], (len(fv), 1)))
        verts, faces = merge(parts)
        body = SkinnedPart("runner", verts, faces, JOINTS, np.concatenate(ji), np.concatenate(ww),
                           self.angles, np.linspace(0, STRIDE, 17), root_offset=self.bob, material="shirt")
        gv, gf, guv = heightfield(8.0, 32, lambda x, z: np.zeros_like(x), uv_repeat=4.0)
        self.parts = [Part("ground", gv, gf, material="ground", uvs=guv), body]
        self.textures = {"track.png": checker(256, 4, (0.55, 0.25, 0.2), (0.65, 0.32, 0.25))}
        self.materials = {"shirt": "{diffuse: [0.2, 0.45, 0.8], specular: 0.2, shininess: 32}",
                          "ground": "{diffuse: [1, 1, 1], texture: track.png}"}
        self.lights = ["{type: point, position: [3, 5, 4], intensity: 45}",
                       "{type: directional, direction: [0.5, -0.7, 0.5], intensity: 0.3}"]
        self.camera = ("camera:\n  interpolation: catmull-rom\n  keys:\n"
                       "    - {t: 0, eye: [1.0, 1.3, 3.3], look_at: [0, 0.9, 0], fov: 40}\n"
                       "    - {t: 1, eye: [2.7, 1.4, 2.0], look_at: [0, 0.9, 0], fov: 40}\n"
                       "    - {t: 2, eye: [3.3, 1.2, -0.4], look_at: [0, 0.9, 0], fov: 40}\n")

    def bob(self, t):
        return np.array([0.0, 0.04 * np.cos(4 * np.pi * t / STRIDE), 0.0])

    def angles(self, t):
        """(13, 3) joint angles in degrees (x, y, z) at time t."""
        w = 2 * np.pi * t / STRIDE
        a = np.zeros((len(JOINTS), 3))
        a[0] = [0, -6 * np.sin(w), 0]
        a[1] = [0, 8 * np.sin(w), -10]
        a[2] = [0, -4 * np.sin(w), 9]
        for side, sign in (("l", 1), ("r", -1)):
            ph = w if sign > 0 else w + np.pi
            base = 3 if side == "l" else 5
            a[base] = [0, 0, -32 * np.sin(ph)]
            a[base + 1] = [0, 0, 70 + 12 * np.sin(ph)]
            leg = 7 if side == "l" else 10
            a[leg] = [0, 0, 38 * np.sin(ph)]
            a[leg + 1] = [0, 0, -(10 + 60 * (0.5 + 0.5 * np.cos(ph)))]
            a[leg + 2] = [0, 0, 12 * np.sin(ph - 0.5)]
        return a
