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

from anim.errors import SceneError
from anim.instances import quaternion_matrices, two_level
from anim.interpolate import wrap_time
from anim.materials import pbr_material
from anim.memory import check_copies
from anim.track_kernels import quat_to_matrix, slerp_into
from anim.vertex_kernels import instances_into, skin_into, transform_into

_DTYPE = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_PATHS = ("translation", "rotation", "scale", "weights")
# geometry stored compressed: without a decoder the accessors would read as zeros or garbage
_COMPRESSED = ("KHR_draco_mesh_compression", "EXT_meshopt_compression", "KHR_meshopt_compression")
_NORMALIZE = {np.int8: 127.0, np.uint8: 255.0, np.int16: 32767.0, np.uint16: 65535.0}


def _field(obj, name, default=None):
    """A field of a glTF object that pygltflib gives as a dataclass or a dict."""
    value = obj.get(name, default) if isinstance(obj, dict) else getattr(obj, name, default)
    return default if value is None else value


def _spec_gloss(material):
    """The KHR_materials_pbrSpecularGlossiness dict of a material, or None."""
    ext = _field(material, "extensions", {}) or {}
    found = ext.get("KHR_materials_pbrSpecularGlossiness") if isinstance(ext, dict) else None
    return found if isinstance(found, dict) else None


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


# a STEP sampler's key time matches the scene time within this many float32
# ulps of the larger of the two (the file stores its times as float32)
KEY_TIME_ULPS = 4


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
        if self.step:
            # a time on a key (within the float32 rounding of the file's key
            # times) takes that key: 25 keys at float32 linspace(0, 1, 25),
            # each a hair above k / 24, would else hold the key before
            near = KEY_TIME_ULPS * np.finfo(np.float32).eps * abs(t)
            return key(max(0, int(np.searchsorted(times, t + near, side="right")) - 1))
        if t <= times[0] or len(times) == 1:
            return key(0)
        if t >= times[-1]:
            return key(len(times) - 1)
        k = int(np.searchsorted(times, t, side="right")) - 1
        h = times[k + 1] - times[k]
        s = (t - times[k]) / h
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

    def __init__(self, path, animation, extrapolate, scene_path, key, warnings=None, instancing="flatten"):
        """instancing: how EXT_mesh_gpu_instancing's copies are made (render.instancing)."""
        self.path, self.scene_path, self.key = Path(path), scene_path, key
        self.instancing = instancing
        self.warnings = warnings if warnings is not None else []
        self.extrapolate = extrapolate
        try:
            self.doc = pygltflib.GLTF2().load(str(path))
        except FileNotFoundError:
            raise SceneError(scene_path, key, f"mesh file not found: {path}") from None
        except Exception as exc:
            raise SceneError(scene_path, key, f"cannot read glTF {path}: {exc}") from None
        if self.doc is None:
            raise SceneError(scene_path, key, f"cannot read glTF {path}")
        for ext in self.doc.extensionsRequired or []:
            if ext in _COMPRESSED:
                raise SceneError(scene_path, key, f"{self.path.name}: needs {ext}, which frustrace does not "
                                                  "read; write the file without it (e.g. gltf-transform copy)")
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

    def _fail(self, problem, key=None):
        raise SceneError(self.scene_path, key or self.key, f"{self.path.name}: {problem}")

    def _fail_animation(self, problem):
        """An error of the file's animations: named under the object's `animation` key."""
        self._fail(problem, self.key.rsplit(".", 1)[0] + ".animation")

    def _buffer(self, i, buf):
        if buf.uri is None:
            return self.doc.binary_blob()
        if buf.uri.startswith("data:"):
            return base64.b64decode(buf.uri.split(",", 1)[1])
        try:
            return (self.path.parent / unquote(buf.uri)).read_bytes()
        except OSError as exc:
            self._fail(f"buffer {i}: cannot read {buf.uri}: {exc.strerror}")

    def _view_array(self, what, view_index, offset, count, dtype, width):
        """(count, width) array read from a buffer view (its byteStride, or packed)."""
        view = self.doc.bufferViews[view_index]
        data = self._buffers[view.buffer]
        stride = view.byteStride or dtype.itemsize * width
        start = (view.byteOffset or 0) + (offset or 0)
        end = start + (count - 1) * stride + dtype.itemsize * width if count > 0 else start
        if count < 0 or start < 0 or stride < dtype.itemsize * width or end > len(data):
            self._fail(f"{what} ({count} x {width} values) reaches byte {end} of a {len(data)}-byte buffer")
        return np.ndarray((count, width), dtype, buffer=data, offset=start,
                          strides=(stride, dtype.itemsize)).copy()

    def accessor(self, index):
        """(count, width) array of an accessor, sparse substitutions applied;
        normalised integers become floats."""
        acc = self.doc.accessors[index]
        dtype = np.dtype(_DTYPE[acc.componentType])
        width = _WIDTH.get(acc.type)
        if width is None:
            self._fail(f"accessor {index} has unsupported type {acc.type}")
        if acc.bufferView is None:
            arr = np.zeros((acc.count, width), dtype)
        else:
            arr = self._view_array(f"accessor {index}", acc.bufferView, acc.byteOffset, acc.count, dtype, width)
        if acc.sparse is not None:
            self._apply_sparse(index, acc, arr, dtype, width)
        if acc.normalized and dtype.type in _NORMALIZE:
            arr = np.maximum(arr / _NORMALIZE[dtype.type], -1.0)
        return arr

    def _apply_sparse(self, index, acc, arr, dtype, width):
        """glTF 2.0 section 3.6.2.3: `count` elements replaced, at the
        positions the indices name, by the values (Blender writes morph
        targets this way)."""
        sparse = acc.sparse
        count = _field(sparse, "count")
        ind, val = _field(sparse, "indices"), _field(sparse, "values")
        if not isinstance(count, int) or count < 1 or ind is None or val is None:
            self._fail(f"accessor {index}: sparse needs a count >= 1, indices and values")
        ind_type = _field(ind, "componentType")
        if ind_type not in (5121, 5123, 5125):
            self._fail(f"accessor {index}: sparse indices must be unsigned integers, not component type {ind_type}")
        positions = self._view_array(f"accessor {index} sparse indices", _field(ind, "bufferView"),
                                     _field(ind, "byteOffset"), count, np.dtype(_DTYPE[ind_type]), 1)[:, 0]
        values = self._view_array(f"accessor {index} sparse values", _field(val, "bufferView"),
                                  _field(val, "byteOffset"), count, dtype, width)
        positions = positions.astype(np.int64)
        if positions.max() >= acc.count or np.any(np.diff(positions) <= 0):
            self._fail(f"accessor {index}: sparse indices must increase and stay below its count {acc.count}")
        arr[positions] = values

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
        self.instances, verts, faces, uvs, face_material, pending = [], [], [], [], [], []
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
                uv = self._primitive_uvs(prim, len(pos))
                copies = self._gpu_instances(node_index, node)
                inst = {"node": node_index, "offset": 0, "rest": np.ascontiguousarray(pos), "copies": copies,
                        "targets": [self.accessor(t["POSITION"]).astype(np.float32)
                                    for t in (prim.targets or []) if t.get("POSITION") is not None],
                        "mesh": node.mesh, "primitive": p_index, "skin": None}
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
                if copies is not None and inst["skin"] is not None:
                    self._fail(f"node {node_index}: a skinned mesh with EXT_mesh_gpu_instancing is not supported")
                pending.append((inst, pos, idx, uv, prim.material))
        # two-level: each GPU-instanced primitive once, and each primitive that
        # several nodes show (no skin, no morph targets) once; instance_matrices places the copies
        tris = [len(idx) // 3 for _, _, idx, _, _ in pending]
        sharing = {}
        for j, (inst, *_) in enumerate(pending):
            if inst["copies"] is None and inst["skin"] is None and not inst["targets"]:
                sharing.setdefault((inst["mesh"], inst["primitive"]), []).append(j)
        sharing = {k: v for k, v in sharing.items() if len(v) > 1}
        gpu = [j for j, (inst, *_) in enumerate(pending) if inst["copies"] is not None]
        copied = (sum(len(pending[j][0]["copies"]) * tris[j] for j in gpu)
                  + sum(len(v) * tris[v[0]] for v in sharing.values()))
        n_copies = sum(len(pending[j][0]["copies"]) for j in gpu) + sum(len(v) for v in sharing.values())
        self.two_level = copied > 0 and two_level(self.instancing, copied, n_copies)
        # where the flattened file numbers each entry's triangles
        flat_at, at = [], 0
        for j, (inst, *_) in enumerate(pending):
            flat_at.append(at)
            at += tris[j] * (1 if inst["copies"] is None else len(inst["copies"]))
        first_of = {v[0]: v for v in sharing.values()} if self.two_level else {}
        shown_by = {j for v in first_of.values() for j in v[1:]}
        self.segments, face0 = [], 0
        for j, (inst, pos, idx, uv, material) in enumerate(pending):
            copies = inst["copies"]
            if copies is not None and not self.two_level:
                check_copies(len(copies) * tris[j], f"node {inst['node']}: {len(copies):,} "
                             "EXT_mesh_gpu_instancing copies", self.scene_path, self.key)
            inst["two_level"] = self.two_level and (copies is not None or j in first_of)
            inst["nodes"] = [pending[m][0]["node"] for m in first_of[j]] if j in first_of else None
            if j in shown_by:                    # a copy of an earlier entry's primitive: no triangles of its own
                continue
            n = 1 if copies is None or inst["two_level"] else len(copies)
            inst["offset"] = offset
            self.instances.append(inst)
            verts.append(np.tile(pos, (n, 1)))
            tri = idx.reshape(-1, 3).astype(np.int64)
            faces.append((tri[None] + offset + (np.arange(n) * len(pos))[:, None, None]).reshape(-1, 3))
            face_material.append(np.full(n * len(tri), -1 if material is None else material, np.int32))
            uvs.append(np.tile(uv, (n, 1)))
            offset += n * len(pos)
            if not inst["two_level"]:
                self.segments.append((face0, face0 + n * len(tri), 0, np.array([flat_at[j]], np.int64)))
            elif copies is not None:
                self.segments.append((face0, face0 + len(tri), len(copies),
                                      flat_at[j] + np.arange(len(copies), dtype=np.int64) * len(tri)))
            else:
                self.segments.append((face0, face0 + len(tri), len(first_of[j]),
                                      np.array([flat_at[m] for m in first_of[j]], np.int64)))
            face0 += n * len(tri)
        blocks = [inst for inst in self.instances if inst["two_level"]]
        self.block_static = [not inst["targets"] for inst in blocks]     # morph targets may move a prototype
        self.instance_slots = [None] * len(blocks)
        self.plain = np.zeros(face0, bool)
        if not self.instances:
            self._fail("the scene has no triangle meshes")
        self.n_vertices = offset
        self.faces = np.ascontiguousarray(np.concatenate(faces), np.int32)
        self.uvs = np.ascontiguousarray(np.concatenate(uvs), np.float32)
        self.rest = np.concatenate(verts)
        # the file's material of each triangle (-1: none), and those materials
        self.face_material = np.concatenate(face_material)
        used = sorted({int(m) for m in np.unique(self.face_material) if m >= 0})
        self.materials = {m: self._material(m) for m in used}

    def _gpu_instances(self, index, node):
        """(n, 4, 4) local transforms of EXT_mesh_gpu_instancing's copies of
        a node's mesh (TRANSLATION, ROTATION x y z w, SCALE; the node's own
        transform applies after them), or None."""
        ext = (node.extensions or {}).get("EXT_mesh_gpu_instancing")
        if ext is None:
            return None
        attrs = ext.get("attributes", {}) if isinstance(ext, dict) else {}
        got = {name: self.accessor(attrs[name]).astype(np.float64) for name in ("TRANSLATION", "ROTATION", "SCALE")
               if name in attrs}
        if not got:
            self._fail(f"node {index}: EXT_mesh_gpu_instancing without TRANSLATION, ROTATION or SCALE")
        n = len(next(iter(got.values())))
        for name, width in (("TRANSLATION", 3), ("ROTATION", 4), ("SCALE", 3)):
            a = got.get(name)
            if a is not None and a.shape != (n, width):
                self._fail(f"node {index}: EXT_mesh_gpu_instancing {name} has shape {a.shape}; expected ({n}, {width})")
            if a is not None and not np.all(np.isfinite(a)):
                self._fail(f"node {index}: EXT_mesh_gpu_instancing {name} holds inf or NaN")
        out = np.tile(np.eye(4), (n, 1, 1))
        rot = got.get("ROTATION")
        if rot is not None:
            norms = np.linalg.norm(rot, axis=1, keepdims=True)
            if np.any(norms < 1e-12):
                self._fail(f"node {index}: EXT_mesh_gpu_instancing ROTATION holds a zero quaternion")
            rot = rot / norms
        if rot is not None:
            out[:, :3, :3] = quaternion_matrices(rot[:, [3, 0, 1, 2]])        # glTF: x y z w
        if "SCALE" in got:
            out[:, :3, :3] *= got["SCALE"][:, None, :]
        if "TRANSLATION" in got:
            out[:, :3, 3] = got["TRANSLATION"]
        return out

    def _texture_info(self, material_index):
        """The base colour (or, in the older specular-glossiness model, the
        diffuse) texture's info of a material, or None."""
        mat = self.doc.materials[material_index]
        gloss = _spec_gloss(mat)
        if gloss is not None:
            return gloss.get("diffuseTexture")
        pbr = mat.pbrMetallicRoughness
        return None if pbr is None else pbr.baseColorTexture

    def _primitive_uvs(self, prim, n):
        """(n, 2) f32 texture coordinates of a primitive for its material's
        base colour texture: the set it names (texCoord), through its
        KHR_texture_transform, v flipped (glTF's v runs down, frustrace's up)."""
        info = self._texture_info(prim.material) if prim.material is not None else None
        transform = (_field(info, "extensions", {}) or {}).get("KHR_texture_transform") if info else None
        texcoord = _field(info, "texCoord", 0) if info else 0
        if transform and "texCoord" in transform:
            texcoord = transform["texCoord"]
        accessor = getattr(prim.attributes, f"TEXCOORD_{texcoord}", None)
        if accessor is None:
            return np.zeros((n, 2), np.float32)
        uv = self.accessor(accessor).astype(np.float64)
        if transform:
            # matrix = translation * rotation * scale (the extension's specification)
            ox, oy = transform.get("offset", (0.0, 0.0))
            sx, sy = transform.get("scale", (1.0, 1.0))
            r = float(transform.get("rotation", 0.0))
            c, s = np.cos(r), np.sin(r)
            u, v = uv[:, 0] * sx, uv[:, 1] * sy
            uv = np.stack([ox + c * u + s * v, oy - s * u + c * v], axis=1)
        uv[:, 1] = 1 - uv[:, 1]
        return uv.astype(np.float32)

    def _material(self, index):
        """A frustrace material from the file's material (anim/materials.py): base
        colour factor and texture as the diffuse term (the texture
        sRGB-decoded, as glTF stores it), roughness and metallic factors."""
        mat = self.doc.materials[index]
        pbr = mat.pbrMetallicRoughness
        colour = list(_field(pbr, "baseColorFactor", [1.0, 1.0, 1.0, 1.0]))[:3] if pbr else [1.0, 1.0, 1.0]
        metallic = float(_field(pbr, "metallicFactor", 1.0)) if pbr else 1.0
        roughness = float(_field(pbr, "roughnessFactor", 1.0)) if pbr else 1.0
        gloss = _spec_gloss(mat)
        if gloss is not None:      # KHR_materials_pbrSpecularGlossiness (older exporters)
            colour = list(gloss.get("diffuseFactor", [1.0, 1.0, 1.0, 1.0]))[:3]
            roughness = 1.0 - float(gloss.get("glossinessFactor", 1.0))
            metallic = (sum(gloss.get("specularFactor", [1.0, 1.0, 1.0])) / 3.0 - 0.04) / 0.96
        texture = None
        info = self._texture_info(index)
        if info is not None and _field(info, "index") is not None:
            texture = self._image(_field(info, "index"))
        return pbr_material(mat.name or f"material {index}", colour, roughness, metallic, texture)

    def _image(self, texture_index):
        """The image of a texture: a path, or (bytes, suffix) for one stored
        in the file (a buffer view or a data: URI)."""
        doc = self.doc
        source = doc.textures[texture_index].source
        if source is None:
            # the image only through an extension (KHR_texture_basisu, EXT_texture_webp): the
            # colour factor alone, as a viewer without the extension shows it
            self.warnings.append(f"{self.key}: {self.path.name}: texture {texture_index} has its image only "
                                 "in an extension frustrace does not read; its material's colour factor is used")
            return None
        image = doc.images[source]
        suffix = {"image/png": ".png", "image/jpeg": ".jpg"}.get(image.mimeType or "", ".png")
        if image.uri is None:
            view = doc.bufferViews[image.bufferView]
            data = self._buffers[view.buffer]
            start = view.byteOffset or 0
            return bytes(data[start:start + view.byteLength]), suffix
        if image.uri.startswith("data:"):
            header = image.uri.split(",", 1)[0]
            suffix = ".jpg" if "jpeg" in header else ".png"
            return base64.b64decode(image.uri.split(",", 1)[1]), suffix
        path = self.path.parent / unquote(image.uri)
        if not path.is_file():
            self._fail(f"image {source}: file not found: {path}")
        return path

    def _chosen(self, which):
        """Indices of the animations `which` names: None (the first), an index,
        a name, "all", or a list of indices and names."""
        names = [a.name for a in self.doc.animations]
        if which is None:
            return [0]
        if which == "all":
            return list(range(len(names)))
        chosen = []
        for item in (which if isinstance(which, list) else [which]):
            if isinstance(item, int):
                if not 0 <= item < len(names):
                    self._fail(f"animation {item} out of range (the file has {len(names)})")
                index = item
            elif item in names:
                index = names.index(item)
            else:
                self._fail(f"no animation named {item!r}; the file has {names}")
            if index in chosen:
                self._fail(f"animation {item!r} is chosen twice")
            chosen.append(index)
        return chosen

    def _label(self, index):
        name = self.doc.animations[index].name
        return f"{index} ({name!r})" if name else str(index)

    def _driven(self, index):
        """(node, path) pairs animation `index` drives."""
        return {(ch.target.node, ch.target.path) for ch in self.doc.animations[index].channels
                if ch.target.node is not None and ch.target.path in _PATHS}

    def _animation(self, which):
        """The channels of the chosen animations, played together. Two of them
        driving one node's same property is an error; an animation left out
        that drives a node property the chosen ones do not is a warning
        (Blender writes one animation per action: the armature's bones in
        one, the mesh's shape-key weights in another)."""
        doc = self.doc
        self.channels = []
        self.t0 = self.t1 = 0.0
        if not doc.animations:
            if which is not None and which != "all":          # all of none: a still object
                self._fail_animation(f"animation {which!r} requested, but the file has none")
            return
        chosen = self._chosen(which)
        owner = {}
        for index in chosen:
            for target in sorted(self._driven(index)):
                if target in owner:
                    self._fail_animation(f"animations {self._label(owner[target])} and {self._label(index)} both "
                                         f"drive node {target[0]}'s {target[1]}; choose one of them")
                owner[target] = index
        for index in range(len(doc.animations)):
            if index in chosen:
                continue
            extra = sorted(self._driven(index) - set(owner))
            if extra:
                what = ", ".join(f"{doc.nodes[n].name or f'node {n}'}'s {p}" for n, p in extra[:4])
                more = f" and {len(extra) - 4} more" if len(extra) > 4 else ""
                self.warnings.append(
                    f"{self.key}: {self.path.name}: animation {self._label(index)} is not played, and it "
                    f"drives {what}{more}, which the played animation(s) do not; "
                    f"'animation: all' (key {self.key.rsplit('.', 1)[0]}.animation) plays every animation")
        starts, ends = [], []
        for index in chosen:
            anim = doc.animations[index]
            for c, ch in enumerate(anim.channels):
                if ch.target.node is None or ch.target.path not in _PATHS:
                    continue
                where = f"animation {self._label(index)} channel {c}"
                if not 0 <= ch.target.node < len(doc.nodes):
                    self._fail_animation(f"{where} targets node {ch.target.node}, but the file has "
                                         f"{len(doc.nodes)} nodes")
                if ch.sampler is None or not 0 <= ch.sampler < len(anim.samplers):
                    self._fail_animation(f"{where} names sampler {ch.sampler}, but the animation has "
                                         f"{len(anim.samplers)}")
                smp = anim.samplers[ch.sampler]
                times = self.accessor(smp.input).reshape(-1).astype(np.float64)
                values = self.accessor(smp.output).astype(np.float64)
                for what, array in (("key times", times), ("key values", values)):
                    if not np.all(np.isfinite(array)):
                        self._fail_animation(f"{where}: its sampler {ch.sampler}'s {what} hold inf or NaN")
                if np.any(np.diff(times) <= 0):
                    self._fail_animation(f"{where}: sampler {ch.sampler}'s key times must increase")
                self.channels.append((ch.target.node, ch.target.path,
                                      _Sampler(times, values, smp.interpolation or "LINEAR",
                                               ch.target.path == "rotation")))
                starts.append(times[0])
                ends.append(times[-1])
        if self.channels:
            self.t0, self.t1 = min(starts), max(ends)

    @property
    def static(self):
        return not self.channels

    @property
    def rigid(self):
        """Moved by node transforms only (no skin, no morph weights)."""
        return self.static or (all(i["skin"] is None for i in self.instances)
                               and not any(path == "weights" for _, path, _ in self.channels))

    def _pose(self, t):
        """(world (n_nodes, 4, 4) matrices, {node: morph weights}) at time t."""
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
        return world, weights

    def instance_matrices(self, t, transform=None):
        """Two-level: per instanced primitive, its copies' (n, 3, 4) matrices
        at time t (the node's world transform after each GPU copy's own, or
        each node's that shows a shared primitive, and `transform` on top)."""
        world, _ = self._pose(t)
        top = np.eye(4)
        if transform is not None:
            top[:3] = transform
        return [(top @ world[inst["node"]] @ inst["copies"])[:, :3] if inst["copies"] is not None
                else np.stack([(top @ world[node])[:3] for node in inst["nodes"]])
                for inst in self.instances if inst["two_level"]]

    def place(self, t, out, transform=None):
        """Posed vertices at time t into out (n, 3) f32; `transform` (3, 4) on top
        (a two-level primitive's stay in its mesh's space: instance_matrices)."""
        world, weights = self._pose(t)
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
            if inst["two_level"]:
                dst[...] = rest
            elif inst["skin"] is not None:
                joints, ibm, joint, weight = inst["skin"]
                mats = np.einsum("ab,jbc,jcd->jad", top, world[joints], ibm)[:, :3]
                skin_into(rest, joint, weight, np.ascontiguousarray(mats), dst)
            elif inst["copies"] is not None:
                dst = out[inst["offset"]:inst["offset"] + len(rest) * len(inst["copies"])]
                instances_into(rest, np.ascontiguousarray((top @ world[inst["node"]] @ inst["copies"])[:, :3]), dst)
            else:
                transform_into(rest, np.ascontiguousarray((top @ world[inst["node"]])[:3]), dst)
