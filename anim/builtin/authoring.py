"""What every built-in scene is made of: parts that know their exact motion
and how to write themselves as frustrace input (meshes, keys, anim.yaml).

A part's `exact(t)` is the ground truth; its keys are samples of it, so the
difference between `AnimatedScene.vertices_at(t)` and `exact(t)` is pure
interpolation error (zero at the keys up to float32 rounding: a test).
Files are written byte-for-byte deterministically (fixed number formats, zip
entries with a fixed date).
"""
import io
import zipfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation


def fmt(x):
    return f"{float(x):.9g}"


def write_obj(path, vertices, faces, uvs=None):
    """Plain OBJ (1-based indices), 6 decimals, optional per-vertex UVs."""
    v = np.asarray(vertices, np.float64)
    f = (np.asarray(faces, np.int64) + 1).tolist()
    # one %-format over all rows: 4x faster than a format per row, same bytes
    text = ("v %.6f %.6f %.6f\n" * len(v)) % tuple(v.ravel().tolist())
    if uvs is not None:
        uv = np.asarray(uvs, np.float64)
        text += ("vt %.6f %.6f\n" * len(uv)) % tuple(uv.ravel().tolist())
        text += "".join("f %d/%d %d/%d %d/%d\n" % (a, a, b, b, c, c) for a, b, c in f)
    else:
        text += ("f %d %d %d\n" * len(f)) % tuple(np.ravel(f).tolist())
    Path(path).write_text(text)


def write_npz(path, **arrays):
    """np.savez with a fixed entry date, so that equal arrays give equal bytes."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, arr in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arr), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, buf.getvalue())


def _keys_yaml(rows):
    return "[" + ", ".join("[" + ", ".join(fmt(x) for x in row) + "]" for row in rows) + "]"


class Part:
    """A named mesh with a material. Subclasses add motion."""
    moving = False

    def __init__(self, name, vertices, faces, material=None, uvs=None, mesh_file=None):
        self.name, self.material = name, material
        self.vertices = np.asarray(vertices, np.float64)
        self.faces = np.asarray(faces, np.int64)
        self.uvs = uvs
        self.mesh_file = mesh_file or f"{name}.obj"     # parts may share one file

    def exact(self, t):
        return self.vertices

    def write(self, out_dir, written):
        if self.mesh_file not in written:
            write_obj(out_dir / self.mesh_file, self.vertices, self.faces, self.uvs)
            written.add(self.mesh_file)
        return f"    mesh: {self.mesh_file}\n"

    def yaml(self, out_dir, written):
        """This part's entry in anim.yaml; writes its files (once per name in `written`)."""
        head = f"  - name: {self.name}\n"
        if self.material:
            head += f"    material: {self.material}\n"
        return head + self.write(out_dir, written)


class RigidPart(Part):
    """Rigid motion v -> R(t) v + T(t), keyed as TRS tracks at `key_times`.
    Rotation keys are kept in one hemisphere (q, not -q, of the previous key)
    and must be less than 180 degrees apart for slerp to follow the motion."""
    moving = True

    def __init__(self, name, vertices, faces, motion, key_times, material=None, uvs=None,
                 interpolation="catmull-rom", rotation="slerp", extrapolate="loop", mesh_file=None):
        super().__init__(name, vertices, faces, material, uvs, mesh_file)
        self.motion, self.key_times = motion, np.asarray(key_times, float)
        self.interpolation, self.rotation, self.extrapolate = interpolation, rotation, extrapolate

    def exact(self, t):
        r, tr = self.motion(t)
        return self.vertices @ np.asarray(r).T + tr

    def write(self, out_dir, written):
        trans, quats, prev = [], [], None
        for t in self.key_times:
            r, tr = self.motion(t)
            q = Rotation.from_matrix(r).as_quat()[[3, 0, 1, 2]]
            if prev is not None and np.dot(q, prev) < 0:
                q = -q
            prev = q
            trans.append([t, *tr])
            quats.append([t, *q])
        return super().write(out_dir, written) + (
            f"    extrapolate: {self.extrapolate}\n    transform:\n"
            f"      translation: {{interpolation: {self.interpolation}, keys: {_keys_yaml(trans)}}}\n"
            f"      rotation: {{interpolation: {self.rotation}, keys: {_keys_yaml(quats)}}}\n")


class InstancedPart(Part):
    """Copies of one mesh, copy i placed by T_i(t) + R_i(t) (S_i * v):
    `motion(t)` gives (T (n, 3), R (n, 3, 3), S (n, 3)), keyed at
    `key_times` into an instance table (.npz); rotations kept in one
    hemisphere key to key, as RigidPart's."""
    moving = True

    def __init__(self, name, vertices, faces, motion, key_times, material=None, interpolation="catmull-rom",
                 extrapolate="loop"):
        super().__init__(name, vertices, faces, material, mesh_file=f"{name}.obj")
        self.motion, self.key_times = motion, np.asarray(key_times, float)
        self.interpolation, self.extrapolate = interpolation, extrapolate
        self.n = len(motion(0.0)[0])

    def exact(self, t):
        tr, r, sc = self.motion(t)
        return (np.einsum("nij,nvj->nvi", r, self.vertices[None] * sc[:, None]) + tr[:, None]).reshape(-1, 3)

    def write(self, out_dir, written):
        trans, quats, scales, prev = [], [], [], None
        for t in self.key_times:
            tr, r, sc = self.motion(t)
            q = Rotation.from_matrix(r).as_quat()[:, [3, 0, 1, 2]]
            if prev is not None:
                q = np.where((np.sum(q * prev, axis=1) < 0)[:, None], -q, q)
            prev = q
            trans.append(tr)
            quats.append(q)
            scales.append(sc)
        write_npz(out_dir / f"{self.name}_instances.npz", t=self.key_times, translation=np.array(trans),
                  rotation=np.array(quats), scale=np.array(scales))
        return super().write(out_dir, written) + (
            f"    instances: {{file: {self.name}_instances.npz, interpolation: {self.interpolation}}}\n"
            f"    extrapolate: {self.extrapolate}\n")


class KeyframedPart(Part):
    """Vertex animation: positions(t) written as one OBJ per key time."""
    moving = True

    def __init__(self, name, positions, faces, key_times, material=None, uvs=None,
                 interpolation="catmull-rom", extrapolate="loop"):
        super().__init__(name, positions(0.0), faces, material, uvs)
        self.positions, self.key_times = positions, np.asarray(key_times, float)
        self.interpolation, self.extrapolate = interpolation, extrapolate

    def exact(self, t):
        return self.positions(t)

    def write(self, out_dir, written):
        (out_dir / self.name).mkdir(exist_ok=True)
        lines = [f"    interpolation: {self.interpolation}\n    extrapolate: {self.extrapolate}\n    keyframes:\n"]
        for k, t in enumerate(self.key_times):
            write_obj(out_dir / self.name / f"key_{k:03d}.obj", self.positions(t), self.faces, self.uvs)
            lines.append(f"      - {{t: {fmt(t)}, mesh: {self.name}/key_{k:03d}.obj}}\n")
        return "".join(lines)


class SkinnedPart(Part):
    """A bind-pose mesh on a skeleton. joints: [(name, parent index or -1,
    origin)], a parent before its children; angles(t) -> (J, 3) degrees about
    the bind-pose x, y, z axes (extrinsic 'xyz'); root_offset(t) -> (3,) moves
    the root joint. Weights: joint (n, k) ints, weight (n, k) summing to 1."""
    moving = True

    def __init__(self, name, vertices, faces, joints, joint, weight, angles, key_times,
                 root_offset=None, material=None, uvs=None, interpolation="catmull-rom",
                 extrapolate="loop"):
        super().__init__(name, vertices, faces, material, uvs)
        self.joints, self.joint, self.weight = joints, np.asarray(joint), np.asarray(weight, float)
        self.angles, self.root_offset = angles, root_offset
        self.key_times = np.asarray(key_times, float)
        self.interpolation, self.extrapolate = interpolation, extrapolate

    def joint_matrices(self, t):
        """(J, 4, 4) world transforms of the posed joints times their inverse
        bind transforms, from the exact angles (float64)."""
        ang = self.angles(t)
        world = []
        for j, (_, parent, origin) in enumerate(self.joints):
            local = np.eye(4)
            local[:3, :3] = Rotation.from_euler("xyz", ang[j], degrees=True).as_matrix()
            base = np.asarray(origin, float) - (np.asarray(self.joints[parent][2], float) if parent >= 0 else 0.0)
            if parent < 0 and self.root_offset is not None:
                base = base + self.root_offset(t)
            local[:3, 3] = base
            world.append(local if parent < 0 else world[parent] @ local)
        unbind = np.tile(np.eye(4), (len(self.joints), 1, 1))
        unbind[:, :3, 3] = -np.array([o for _, _, o in self.joints], float)
        return np.stack(world) @ unbind

    def exact(self, t):
        m = self.joint_matrices(t)[self.joint]                   # (n, k, 4, 4)
        moved = np.einsum("nkab,nb->nka", m[..., :3, :3], self.vertices) + m[..., :3, 3]
        return np.einsum("nk,nka->na", self.weight, moved)

    def write(self, out_dir, written):
        write_npz(out_dir / f"{self.name}_weights.npz", joints=self.joint.astype(np.int32),
                  weights=self.weight.astype(np.float32))
        out = [super().write(out_dir, written), f"    extrapolate: {self.extrapolate}\n    skeleton:\n"
               f"      weights: {self.name}_weights.npz\n      joints:\n"]
        ang = np.stack([self.angles(t) for t in self.key_times])         # (K, J, 3)
        for j, (name, parent, origin) in enumerate(self.joints):
            out.append(f"        - name: {name}\n")
            if parent >= 0:
                out.append(f"          parent: {self.joints[parent][0]}\n")
            out.append(f"          origin: [{', '.join(fmt(x) for x in origin)}]\n")
            rows = [[t, *a] for t, a in zip(self.key_times, ang[:, j])]
            out.append(f"          angles: {{order: xyz, interpolation: {self.interpolation}, "
                       f"keys: {_keys_yaml(rows)}}}\n")
            if parent < 0 and self.root_offset is not None:
                rows = [[t, *self.root_offset(t)] for t in self.key_times]
                out.append(f"          translation: {{interpolation: {self.interpolation}, "
                           f"keys: {_keys_yaml(rows)}}}\n")
        return "".join(out)


class BuiltinScene:
    """A generated scene: parts, camera, lights, materials, textures.
    Subclasses fill these in `build()`; `exact(t)` concatenates the parts'
    exact positions in file order (the order of AnimatedScene's vertices)."""
    name = ""
    description = ""
    target_triangles = 0        # the classic scene's size this one is modelled on
    period = 1.0                # the motion repeats (or the animation lasts) this long
    frames = (0, 47, 24)
    resolution = (1024, 1024)

    def __init__(self):
        self.parts, self.materials, self.textures, self.lights = [], {}, {}, []
        self.camera = ""
        self.render = ""            # an optional `render:` line of anim.yaml
        self.build()

    def build(self):
        raise NotImplementedError

    @property
    def triangles(self):
        return sum(getattr(p, "n", 1) * len(p.faces) for p in self.parts)

    def exact(self, t):
        return np.concatenate([p.exact(t) for p in self.parts])

    def exact_moving(self, t):
        """exact(t) of the moving parts only (what interpolation can get wrong)."""
        return np.concatenate([p.exact(t) for p in self.parts if p.moving])

    def write(self, out_dir):
        """Write DIR/anim.yaml with its meshes, weights and textures."""
        from raycore.images.image_io import write_texture
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        for file, pixels in self.textures.items():
            write_texture(str(out_dir / file), pixels)
        start, end, fps = self.frames
        text = [f"# frustrace built-in scene '{self.name}': {self.description}\n",
                "version: 1\n", f"frames: {{start: {start}, end: {end}, fps: {fps}}}\n",
                f"output: {{path: out/{self.name}_####.exr, resolution: [{self.resolution[0]}, {self.resolution[1]}]}}\n",
                self.camera, self.render, "lights:\n"]
        text += [f"  - {light}\n" for light in self.lights]
        text.append("materials:\n")
        text += [f"  {name}: {m}\n" for name, m in self.materials.items()]
        text.append("objects:\n")
        written = set()
        text += [p.yaml(out_dir, written) for p in self.parts]
        (out_dir / "anim.yaml").write_text("".join(text))
        return out_dir / "anim.yaml"


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def chain_weights(s, stops, joints, parent, blend):
    """Two-influence skin weights for a limb parametrised by s in [0, 1].

    stops[i] is where joint joints[i] takes over (stops[0] = 0, at the limb's
    root, where it takes over from `parent`); within +-blend of a stop the
    weight passes smoothly from the previous joint to the next.
    Returns joint (n, 2) ints and weight (n, 2)."""
    s = np.asarray(s, float)
    stops = np.asarray(stops, float)
    seg = np.searchsorted(stops[1:], s, side="right")
    ji = np.zeros((len(s), 2), int)
    w = np.zeros((len(s), 2))
    ji[:, 0] = np.asarray(joints)[seg]
    w[:, 0] = 1.0
    for i, stop in enumerate(stops):
        near = np.abs(s - stop) < blend
        frac = _smoothstep((s[near] - (stop - blend)) / (2 * blend))
        before = parent if i == 0 else joints[i - 1]
        ji[near] = np.stack([np.full(near.sum(), before), np.full(near.sum(), joints[i])], -1)
        w[near] = np.stack([1 - frac, frac], -1)
    return ji, w
