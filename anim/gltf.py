"""glTF 2.0 objects (.gltf / .glb) and their animations, read with pygltflib.

trimesh loads glTF geometry but does not evaluate animations, so this module
does: node TRS channels (STEP, LINEAR with shortest-arc slerp, CUBICSPLINE),
skins (joint matrices x inverse bind matrices, linear blend skinning) and
morph targets (POSITION deltas weighted by animated or default weights).
All mesh primitives of the file's default scene form one frustrace object.
Evaluation follows the glTF 2.0 specification, section 3.11 (animations) and
3.7.3 (skins: a skinned mesh ignores its node's transform).
"""
import base64
from pathlib import Path
from urllib.parse import unquote

import numpy as np
import pygltflib

from .errors import SceneError
from .interpolate import wrap_time
from .track_kernels import quat_to_matrix, slerp_into
from .vertex_kernels import skin_into, transform_into

_DTYPE = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_NORMALIZE = {np.int8: 127.0, np.uint8: 255.0, np.int16: 32767.0, np.uint16: 65535.0}


def _quat_matrix(q):
    """3x3 rotation of a unit quaternion (x, y, z, w), glTF order."""
    out = np.empty((3, 3))
    quat_to_matrix(q[3], q[0], q[1], q[2], out)
    return out


def slerp(q0, q1, s):
    """Shortest-arc slerp of unit quaternions (track_kernels.slerp_into, the
    one every rotation track uses)."""
    out = np.empty(4, np.float64)
    slerp_into(np.asarray(q0, np.float64), np.asarray(q1, np.float64), float(s), out)
    return out


class _Sampler:
    """One animation sampler: key times, values and interpolation."""

    def __init__(self, times, values, interpolation, is_rotation):
        self.times = times
        k = len(times)
        self.cubic = interpolation == "CUBICSPLINE"
        self.values = values.reshape(k, 3, -1) if self.cubic else values.reshape(k, -1)
        self.step = interpolation == "STEP"
        self.is_rotation = is_rotation

    def __call__(self, t):
        times, v = self.times, self.values
        key = (lambda i: v[i, 1]) if self.cubic else (lambda i: v[i])
        if t <= times[0] or len(times) == 1:
            return key(0)
        if t >= times[-1]:
            return key(len(times) - 1)
        k = int(np.searchsorted(times, t, side="right")) - 1
        h = times[k + 1] - times[k]
        s = (t - times[k]) / h
        if self.step:
            return key(k)
        if self.cubic:   # Hermite with the stored out/in tangents, scaled by h
            s2, s3 = s * s, s * s * s
            out = ((2 * s3 - 3 * s2 + 1) * v[k, 1] + (s3 - 2 * s2 + s) * h * v[k, 2]
                   + (-2 * s3 + 3 * s2) * v[k + 1, 1] + (s3 - s2) * h * v[k + 1, 0])
            return out / np.linalg.norm(out) if self.is_rotation else out
        if self.is_rotation:
            return slerp(v[k], v[k + 1], s)
        return v[k] + s * (v[k + 1] - v[k])


class GltfObject:
    """Geometry and motion of one glTF file; `place(t, out, transform)` writes
    the posed vertices (n, 3) f32."""

    def __init__(self, path, animation, extrapolate, scene_path, key):
        self.path, self.scene_path, self.key = Path(path), scene_path, key
        self.extrapolate = extrapolate
        try:
            self.doc = pygltflib.GLTF2().load(str(path))
        except FileNotFoundError:
            raise SceneError(scene_path, key, f"mesh file not found: {path}") from None
        except Exception as exc:
            raise SceneError(scene_path, key, f"cannot read glTF {path}: {exc}") from None
        if self.doc is None:
            raise SceneError(scene_path, key, f"cannot read glTF {path}")
        try:
            self._buffers = [self._buffer(i, b) for i, b in enumerate(self.doc.buffers)]
            self._nodes()
            self._meshes()
            self._animation(animation)
        except SceneError:
            raise
        except (IndexError, KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
            # an index past its array, a missing or mistyped field: the file is malformed
            raise SceneError(scene_path, key, f"{Path(path).name}: malformed glTF "
                                              f"({type(exc).__name__}: {exc})") from None

    def _fail(self, problem):
        raise SceneError(self.scene_path, self.key, f"{self.path.name}: {problem}")

    def _buffer(self, i, buf):
        if buf.uri is None:
            return self.doc.binary_blob()
        if buf.uri.startswith("data:"):
            return base64.b64decode(buf.uri.split(",", 1)[1])
        try:
            return (self.path.parent / unquote(buf.uri)).read_bytes()
        except OSError as exc:
            self._fail(f"buffer {i}: cannot read {buf.uri}: {exc.strerror}")

    def accessor(self, index):
        """(count, width) array of an accessor; normalised integers become floats."""
        acc = self.doc.accessors[index]
        if acc.sparse is not None:
            self._fail(f"accessor {index} is sparse; sparse accessors are not supported")
        dtype = np.dtype(_DTYPE[acc.componentType])
        width = _WIDTH.get(acc.type)
        if width is None:
            self._fail(f"accessor {index} has unsupported type {acc.type}")
        if acc.bufferView is None:
            return np.zeros((acc.count, width), dtype)
        view = self.doc.bufferViews[acc.bufferView]
        data = self._buffers[view.buffer]
        stride = view.byteStride or dtype.itemsize * width
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        end = start + (acc.count - 1) * stride + dtype.itemsize * width if acc.count > 0 else start
        if acc.count < 0 or start < 0 or stride < dtype.itemsize * width or end > len(data):
            self._fail(f"accessor {index} ({acc.count} x {acc.type}) reaches byte {end} of a "
                       f"{len(data)}-byte buffer")
        arr = np.ndarray((acc.count, width), dtype, buffer=data, offset=start,
                         strides=(stride, dtype.itemsize)).copy()
        if acc.normalized and dtype.type in _NORMALIZE:
            arr = np.maximum(arr / _NORMALIZE[dtype.type], -1.0)
        return arr

    def _nodes(self):
        doc = self.doc
        n = len(doc.nodes)
        self.rest_t, self.rest_r, self.rest_s = np.zeros((n, 3)), np.zeros((n, 4)), np.ones((n, 3))
        self.rest_r[:, 3] = 1
        self.fixed_matrix = [None] * n
        for i, node in enumerate(doc.nodes):
            if node.matrix is not None:
                self.fixed_matrix[i] = np.asarray(node.matrix, np.float64).reshape(4, 4).T   # column-major
            if node.translation is not None:
                self.rest_t[i] = node.translation
            if node.rotation is not None:
                self.rest_r[i] = node.rotation
            if node.scale is not None:
                self.rest_s[i] = node.scale
        scene = doc.scenes[doc.scene or 0] if doc.scenes else None
        if scene is not None:
            roots = list(scene.nodes)
        else:
            children = {c for node in doc.nodes for c in (node.children or [])}
            roots = [i for i in range(n) if i not in children]
        self.order, self.parent = [], np.full(n, -1)
        stack = list(reversed(roots))
        while stack:                              # parents before children
            i = stack.pop()
            if i in self.order:
                self._fail(f"node {i} appears twice in the hierarchy")
            self.order.append(i)
            for c in doc.nodes[i].children or []:
                self.parent[c] = i
                stack.append(c)

    def _meshes(self):
        doc = self.doc
        self.instances, verts, faces, uvs = [], [], [], []
        offset = 0
        for node_index in self.order:
            node = doc.nodes[node_index]
            if node.mesh is None:
                continue
            mesh = doc.meshes[node.mesh]
            for p_index, prim in enumerate(mesh.primitives):
                if prim.mode not in (None, 4):
                    self._fail(f"mesh {node.mesh} primitive {p_index}: mode {prim.mode} (only triangles are supported)")
                attrs = prim.attributes
                if attrs.POSITION is None:
                    self._fail(f"mesh {node.mesh} primitive {p_index} has no POSITION")
                pos = self.accessor(attrs.POSITION).astype(np.float32)
                idx = (self.accessor(prim.indices).reshape(-1) if prim.indices is not None
                       else np.arange(len(pos)))
                if len(idx) % 3 or (len(idx) and idx.max() >= len(pos)):
                    self._fail(f"mesh {node.mesh} primitive {p_index}: bad triangle indices")
                uv = (self.accessor(attrs.TEXCOORD_0).astype(np.float32) if attrs.TEXCOORD_0 is not None
                      else np.zeros((len(pos), 2), np.float32))
                uv[:, 1] = 1 - uv[:, 1]               # glTF v runs down, frustrace's up
                inst = {"node": node_index, "offset": offset, "rest": np.ascontiguousarray(pos),
                        "targets": [self.accessor(t["POSITION"]).astype(np.float32)
                                    for t in (prim.targets or []) if t.get("POSITION") is not None],
                        "mesh": node.mesh, "skin": None}
                weights = getattr(node, "weights", None)       # pygltflib drops node.weights
                weights = weights if weights is not None else mesh.weights
                inst["morph_weights"] = np.asarray(weights if weights is not None else
                                                   [0.0] * len(inst["targets"]), np.float64)
                if node.skin is not None and attrs.JOINTS_0 is not None and attrs.WEIGHTS_0 is not None:
                    skin = doc.skins[node.skin]
                    joint = self.accessor(attrs.JOINTS_0).astype(np.int32)
                    weight = self.accessor(attrs.WEIGHTS_0).astype(np.float64)
                    sums = weight.sum(axis=1, keepdims=True)
                    weight = np.where(sums > 0, weight / np.where(sums > 0, sums, 1), 0)
                    ibm = (self.accessor(skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
                           if skin.inverseBindMatrices is not None else np.tile(np.eye(4), (len(skin.joints), 1, 1)))
                    if joint.max() >= len(skin.joints):
                        self._fail(f"mesh {node.mesh}: JOINTS_0 index beyond skin {node.skin}'s joints")
                    inst["skin"] = (np.asarray(skin.joints), ibm.astype(np.float64),
                                    np.ascontiguousarray(joint), np.ascontiguousarray(weight, np.float32))
                self.instances.append(inst)
                verts.append(pos)
                faces.append(idx.reshape(-1, 3).astype(np.int32) + offset)
                uvs.append(uv)
                offset += len(pos)
        if not self.instances:
            self._fail("the scene has no triangle meshes")
        self.n_vertices = offset
        self.faces = np.ascontiguousarray(np.concatenate(faces), np.int32)
        self.uvs = np.ascontiguousarray(np.concatenate(uvs), np.float32)
        self.rest = np.concatenate(verts)

    def _animation(self, which):
        doc = self.doc
        self.channels = []
        self.t0 = self.t1 = 0.0
        if not doc.animations:
            if which is not None:
                self._fail(f"animation {which!r} requested, but the file has none")
            return
        names = [a.name for a in doc.animations]
        if which is None:
            index = 0
        elif isinstance(which, int):
            index = which
            if not 0 <= index < len(names):
                self._fail(f"animation {which} out of range (the file has {len(names)})")
        elif which in names:
            index = names.index(which)
        else:
            self._fail(f"no animation named {which!r}; the file has {names}")
        anim = doc.animations[index]
        starts, ends = [], []
        for ch in anim.channels:
            if ch.target.node is None or ch.target.path not in ("translation", "rotation", "scale", "weights"):
                continue
            smp = anim.samplers[ch.sampler]
            times = self.accessor(smp.input).reshape(-1).astype(np.float64)
            if np.any(np.diff(times) <= 0):
                self._fail(f"animation {index} sampler {ch.sampler}: key times must increase")
            values = self.accessor(smp.output).astype(np.float64)
            self.channels.append((ch.target.node, ch.target.path,
                                  _Sampler(times, values, smp.interpolation or "LINEAR", ch.target.path == "rotation")))
            starts.append(times[0])
            ends.append(times[-1])
        if self.channels:
            self.t0, self.t1 = min(starts), max(ends)

    @property
    def static(self):
        return not self.channels

    def place(self, t, out, transform=None):
        """Posed vertices at time t into out (n, 3) f32; `transform` (3, 4) on top."""
        t = wrap_time(t, self.t0, self.t1, self.extrapolate)
        trans, rot, scale = self.rest_t.copy(), self.rest_r.copy(), self.rest_s.copy()
        weights = {}
        for node, path, sampler in self.channels:
            value = sampler(t)
            if path == "translation":
                trans[node] = value
            elif path == "rotation":
                rot[node] = value / np.linalg.norm(value)
            elif path == "scale":
                scale[node] = value
            else:
                weights[node] = value
        world = np.zeros((len(self.doc.nodes), 4, 4))
        for i in self.order:
            local = self.fixed_matrix[i]
            if local is None:
                local = np.eye(4)
                local[:3, :3] = _quat_matrix(rot[i]) * scale[i][None, :]
                local[:3, 3] = trans[i]
            p = self.parent[i]
            world[i] = local if p < 0 else world[p] @ local
        top = np.eye(4)
        if transform is not None:
            top[:3] = transform
        for inst in self.instances:
            rest = inst["rest"]
            w = weights.get(inst["node"], inst["morph_weights"])
            if inst["targets"] and np.any(w):
                rest = rest.astype(np.float64)
                for wk, target in zip(w, inst["targets"]):
                    rest = rest + wk * target
                rest = np.ascontiguousarray(rest, np.float32)
            dst = out[inst["offset"]:inst["offset"] + len(rest)]
            if inst["skin"] is not None:
                joints, ibm, joint, weight = inst["skin"]
                mats = np.einsum("ab,jbc,jcd->jad", top, world[joints], ibm)[:, :3]
                skin_into(rest, joint, weight, np.ascontiguousarray(mats), dst)
            else:
                transform_into(rest, np.ascontiguousarray((top @ world[inst["node"]])[:3]), dst)
