"""An animated scene: the validated scene file plus everything precomputed to
produce vertex positions at any time.

Work a scene does not need is left out: a static object (one mesh, or one
keyframe, or constant tracks) is placed once; a rigid object costs one 4x4
transform per frame; only deforming objects evaluate per-vertex curves.
"""
import json
import re
from pathlib import Path

import numpy as np
import yaml
from pydantic import ValidationError

from anim.area_lights import emitter_positions
from anim.errors import SceneError
from anim.instances import InstanceTable, two_level
from anim.keyframes import KeyStore, LinearKeys
from anim.memory import check_copies
from anim.interpolate import Curve
from anim.materials import DEFAULT_MATERIAL
from anim.io.mesh_io import load_mesh, vertex_lines
from anim.rig import Skeleton
from anim.rigid_batch import RigidBatch
from anim.schema import SceneFile, parse_scene
from anim.io.usd import UsdObject, is_usd, scene_of_stage
from anim.io.usd import dependencies as usd_dependencies
from anim.tracks import check_times, compose, rotation_curve, trs_matrix, vector_curve
from anim.vertex_kernels import instances_into, skin_into, transform_into


def _key_path(loc):
    return ".".join(str(p) for p in loc)


class _UniqueKeyLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """YAML's safe loader that rejects a mapping key given twice (plain YAML
    keeps the last one silently). libyaml's parser where PyYAML has it:
    100x faster than the pure-Python one on long key lists."""

    def construct_mapping(self, node, deep=False):
        seen = {}
        for key_node, _ in node.value:
            # the keys written here (merged '<<' keys may be overridden)
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=deep)
            first = seen.setdefault(key, key_node)
            if first is not key_node:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r} (first at line {first.start_mark.line + 1})",
                    key_node.start_mark)
        return super().construct_mapping(node, deep=deep)


# YAML 1.2's floats: PyYAML (YAML 1.1) reads 1e37 and 1E-5, without a dot, as
# strings, which the strict schema would refuse; they are numbers to a user
_UniqueKeyLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))


def read_scene_file(path, camera=None, notes=None, instancing="auto") -> SceneFile:
    """The validated scene of a scene file, or of a whole USD stage or FBX
    file (with `camera`, a camera's prim path or node name; what the file
    gave appended to notes; instancing: how a stage's instances are traced)."""
    path = Path(path)
    if is_usd(path) or path.suffix.lower() == ".fbx":
        if is_usd(path):
            data, file_notes = scene_of_stage(path, camera, instancing)
        else:
            from anim.io.fbx_scene import scene_of_fbx          # a ufbx process only for FBX files
            data, file_notes = scene_of_fbx(path, camera)
        if notes is not None:
            notes.extend(file_notes)
        try:
            return parse_scene(data)
        except ValidationError as exc:
            err = exc.errors()[0]
            raise SceneError(path, _key_path(err["loc"]) or "(top)", f"from the file: {err['msg']}") from None
    if camera is not None:
        raise SceneError(path, "--camera", "chooses a camera of a USD stage or FBX file; this is a scene file")
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise SceneError(path, "", "file not found") from None
    except OSError as exc:
        raise SceneError(path, "", f"cannot read: {exc.strerror}") from None
    try:
        data = yaml.load(text, Loader=_UniqueKeyLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise SceneError(path, "", f"invalid YAML{where}: {problem}") from None
    if not isinstance(data, dict):
        raise SceneError(path, "", "top level must be a mapping")
    try:
        return parse_scene(data)
    except TypeError as exc:
        raise SceneError(path, "", str(exc)) from None
    except ValidationError as exc:
        err = exc.errors()[0]
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            msg = "unknown key"
        elif err["type"] in ("int_type", "float_type", "bool_type", "string_type"):
            msg += f", not {json.dumps(err['input'])}"      # `samples: true` reads "..., not true"
        raise SceneError(path, _key_path(err["loc"]) or "(top)", msg) from None


class SceneObject:
    """One object's geometry and motion; `place(t, out)` writes its (n_v, 3) f32
    positions. Kinds: vertex keyframes (a Curve per vertex coordinate), a mesh
    with a skeleton (skinning), a glTF file, or a mesh with a TRS transform
    (one matrix per frame)."""

    def __init__(self, spec, scene_path, index, warnings, instancing="flatten"):
        """instancing: how an instance table's copies are made (render.instancing)."""
        base = Path(scene_path).parent
        key = f"objects.{index}"
        owner = f"object {spec.name!r}"
        self.name = spec.name
        self.curve = self.skeleton = self.gltf = self.usd = self.fbx = None
        self.translation = self.rotation = self.scale = None
        if spec.keyframes is not None:
            self._keyframes(spec, base, scene_path, key, owner)
        elif spec.mesh.lower().endswith((".gltf", ".glb")):
            from anim.io.gltf import GltfObject          # pygltflib only for scenes with glTF files
            self.gltf = GltfObject(base / spec.mesh, spec.animation, spec.extrapolate, scene_path, f"{key}.mesh",
                                   warnings, "flatten" if spec.instances is not None else instancing)
            self.base, self.faces, self.uvs = self.gltf.rest.astype(np.float32), self.gltf.faces, self.gltf.uvs
        elif spec.mesh.lower().endswith(".fbx"):
            from anim.io.fbx import FbxObject            # a ufbx process only for scenes with FBX files
            self.fbx = FbxObject(base / spec.mesh, spec.animation, spec.extrapolate, scene_path, f"{key}.mesh",
                                 warnings)
            self.base, self.faces, self.uvs = self.fbx.rest.astype(np.float32), self.fbx.faces, self.fbx.uvs
        elif is_usd(spec.mesh):
            self.usd = UsdObject(base / spec.mesh, spec.prim, scene_path, f"{key}.mesh",
                                 "flatten" if spec.instances is not None else instancing)
            self.base, self.faces, self.uvs = self.usd.rest.astype(np.float32), self.usd.faces, self.usd.uvs
        else:
            self.base, self.faces, self.uvs = load_mesh(base / spec.mesh, scene_path, f"{key}.mesh")
            if spec.skeleton is not None:
                self.skeleton = Skeleton(spec.skeleton, len(self.base), scene_path, f"{key}.skeleton",
                                         owner, spec.extrapolate, warnings)
        tr = spec.transform
        if tr is not None:
            if tr.translation is not None:
                self.translation = vector_curve(tr.translation, scene_path, f"{key}.transform.translation",
                                                owner, spec.extrapolate)
            if tr.scale is not None:
                self.scale = vector_curve(tr.scale, scene_path, f"{key}.transform.scale", owner, spec.extrapolate)
            if tr.rotation is not None:
                self.rotation = rotation_curve(tr.rotation, scene_path, f"{key}.transform.rotation", owner,
                                               spec.extrapolate, warnings)
        self.has_transform = any(c is not None for c in (self.translation, self.rotation, self.scale))
        # a file that brings its own motion and materials
        self.file = next((f for f in (self.gltf, self.usd, self.fbx) if f is not None), None)
        self.rigid = self.curve is None and self.skeleton is None and (self.file is None or self.file.rigid)
        self.static = (self.curve is None
                       and (self.skeleton is None or self.skeleton.constant)
                       and (self.file is None or self.file.static)
                       and all(c is None or c.constant for c in (self.translation, self.rotation, self.scale)))
        self.n_vertices = len(self.base)
        self.instances = None
        # a USD file's point instancers' or a glTF file's GPU-instanced copies, two-level
        self.two_level = self.file is not None and getattr(self.file, "two_level", False)
        self.proto_static = self.static
        if spec.instances is not None:
            self._instance(spec, base, scene_path, key, owner, instancing)

    def _instance(self, spec, base, scene_path, key, owner, instancing):
        """Copies of this object by an instance table (anim/instances.py):
        the faces (and UVs) repeated a copy after another, the object as
        written becoming the prototype, placed into a buffer of its own; or,
        two-level (render.instancing), the prototype alone among the
        frame's triangles and the copies as its instances (instances_at)."""
        table = InstanceTable(spec.instances, base, scene_path, f"{key}.instances", owner, spec.extrapolate)
        copied = table.n * len(self.faces)
        if two_level(instancing, copied, table.n):
            self.instances, self.two_level, self.proto_faces = table, True, self.faces
            self.static = self.static and table.constant
            return
        nv = len(self.base)
        check_copies(table.n * len(self.faces), f"{table.n:,} copies of {len(self.faces):,} triangles", scene_path,
                     f"{key}.instances")
        if table.n * max(nv, len(self.faces)) >= 2 ** 31:
            raise SceneError(scene_path, f"{key}.instances", f"{table.n} copies of {len(self.faces)} triangles "
                                                             "are more than 2^31 vertices or triangles")
        self.instances = table
        self.proto_faces = self.faces
        self.faces = np.ascontiguousarray((self.faces[None] + (np.arange(table.n) * nv)[:, None, None])
                                          .reshape(-1, 3), np.int32)
        if self.uvs is not None:
            self.uvs = np.tile(self.uvs, (table.n, 1))
        self.n_vertices = table.n * nv
        self._proto = np.empty((nv, 3), np.float32)
        self.rigid = False
        self.static = self.static and table.constant

    def _keyframes(self, spec, base, scene_path, key, owner):
        """Vertex keyframes, read one file at a time and checked against the
        first (vertex count, faces, an OBJ's vertex lines); kept as float32
        keys (anim/keyframes.py) for linear interpolation, as a Curve of
        per-segment coefficients for the smooth methods."""
        times = check_times([k.t for k in spec.keyframes], scene_path, f"{key}.keyframes", owner)
        linear = spec.interpolation == "linear" or (len(times) == 2 and
                                                    spec.interpolation not in ("clamped", "centripetal"))
        store = KeyStore() if linear else None
        stack, written0, constant = [], None, True
        for i, k in enumerate(spec.keyframes):
            v, f, uv = load_mesh(base / k.mesh, scene_path, f"{key}.keyframes.{i}.mesh")
            written = vertex_lines(base / k.mesh) if k.mesh.lower().endswith(".obj") else None
            if i == 0:
                self.base, self.faces, self.uvs, written0 = v, f, uv, written
            else:
                if written != written0 and None not in (written, written0):
                    raise SceneError(scene_path, f"{key}.keyframes.{i}.mesh",
                                     f"{k.mesh} writes {written} vertices, keyframe 0 "
                                     f"({spec.keyframes[0].mesh}) {written0}: the files' vertex lists "
                                     "must correspond line by line")
                if v.shape != self.base.shape or not np.array_equal(f, self.faces):
                    raise SceneError(scene_path, f"{key}.keyframes.{i}.mesh",
                                     f"has {len(v)} vertices / {len(f)} faces, keyframe 0 has "
                                     f"{len(self.base)} / {len(self.faces)} (or different faces)")
                constant = constant and np.array_equal(v, self.base)
            if store is not None:
                store.add(v)
            else:
                stack.append(v)
        if len(times) == 1 or constant:
            return
        if store is not None:
            self.curve = LinearKeys(times, store, spec.extrapolate)
        else:
            self.curve = Curve(times, np.stack(stack), spec.interpolation, spec.extrapolate)

    def moving_curves(self):
        """The keyed curves that move this object (each with times,
        extrapolate), or None when a glTF or USD file moves it by its own
        animation."""
        if (self.file is not None and not self.file.static) or (self.instances is not None
                                                                 and not self.instances.constant):
            return None
        curves = [self.curve, self.translation, self.rotation, self.scale]
        if self.skeleton is not None:
            curves += self.skeleton.rotation + self.skeleton.translation
        curves = [getattr(c, "curve", c) for c in curves]          # a joint's AngleCurve holds a Curve
        return [c for c in curves if c is not None and not c.constant]

    def held_over(self, t0, t1) -> bool:
        """Whether the object cannot move within [t0, t1]: static, or every
        curve that moves it is clamped and the interval lies before its first
        key or after its last. Conservative: a pause between equal keys, or
        a file's own animation, counts as moving."""
        if self.static:
            return True
        curves = self.moving_curves()
        return curves is not None and all(c.extrapolate == "clamp" and (t1 <= c.times[0] or t0 >= c.times[-1])
                                          for c in curves)

    def segments(self):
        """(first face, end, copies, where) of the object's faces: copies >
        0 for a two-level prototype (its faces once here, each copy's in the
        flattened world), 0 for faces placed as they are; where: each copy's
        (or the faces') first triangle in the flattened object."""
        n = len(self.faces)
        if self.two_level and self.instances is not None:
            return [(0, n, self.instances.n, np.arange(self.instances.n, dtype=np.int64) * n)]
        if self.two_level:
            return self.file.segments
        return [(0, n, 0, np.zeros(1, np.int64))]

    def blocks(self):
        """Per two-level prototype: (whether it deforms, its copies' material
        slots in the file or None)."""
        if self.instances is not None:
            return [(not self.proto_static, None)]
        return [(not static, slots) for static, slots in zip(self.file.block_static, self.file.instance_slots)]

    def instance_matrices(self, t):
        """Per two-level prototype, its copies' (n, 3, 4) world-from-prototype matrices at time t."""
        if self.instances is not None:
            return [self.instances.matrices(t)]
        top = trs_matrix(self.translation, self.rotation, self.scale, t) if self.has_transform else None
        return self.file.instance_matrices(t, top)

    def place(self, t, out):
        """Write the positions at time t into out (n_v, 3) f32 (a two-level
        object's: its prototypes' in their own space)."""
        if self.instances is None or self.two_level:
            self._place_one(t, out)
            return
        self._place_one(t, self._proto)
        instances_into(self._proto, self.instances.matrices(t), out)

    def _place_one(self, t, out):
        """The object as written (an instanced object's prototype) at time t into out."""
        if self.curve is not None:
            self.curve.eval_into(t, out)
            return
        top = trs_matrix(self.translation, self.rotation, self.scale, t) if self.has_transform else None
        if self.file is not None:
            self.file.place(t, out, top)
        elif self.skeleton is not None:
            mats = self.skeleton.matrices(t)
            if top is not None:
                mats = compose(top, mats)
            skin_into(self.base, self.skeleton.joint, self.skeleton.weight, np.ascontiguousarray(mats), out)
        elif top is not None:
            transform_into(self.base, top, out)
        else:
            out[...] = self.base


class AnimatedScene:
    """Loads and checks a scene file; evaluates geometry and camera at time t."""

    def __init__(self, path, camera=None, instancing=None):
        """camera: for a USD stage, the path of the camera prim to render
        through (default: its first camera). instancing: render.instancing's
        choice instead of the file's."""
        self.path = Path(path)
        self.camera_choice, self.instancing_choice = camera, instancing
        self.notes = []            # what a USD stage gave and what came from defaults (`check`)
        self.spec = read_scene_file(self.path, camera, self.notes, instancing or "auto")
        spec = self.spec
        # materials: the file's, plus a default for objects that name none
        self.material_names = list(spec.materials)
        self.materials = [m.model_dump() for m in spec.materials.values()] + [DEFAULT_MATERIAL]
        self.texture_paths = []
        self.texture_spaces = []       # "auto" | "srgb" | "linear", one per texture
        self.texture_keys = []         # "materials.NAME.texture", for errors
        for name, m in zip(self.material_names + ["(default)"], self.materials):
            source = None
            if m["texture"]:
                source = self.path.parent / m["texture"]
                if not source.is_file():
                    raise SceneError(self.path, f"materials.{name}.texture", f"file not found: {source}")
            self._add_texture(m, source, f"materials.{name}.texture")
        default_material = len(self.material_names)
        self.warnings = []         # e.g. quaternions normalised; the CLI prints them
        self.objects = []
        offset = 0
        faces, mats, uvs = [], [], []
        any_uv_needed = False
        names = {}
        for i, o in enumerate(spec.objects):
            if o.name in names:
                raise SceneError(self.path, f"objects.{i}.name",
                                 f"{o.name!r} is also the name of objects.{names[o.name]}; names must be unique")
            names[o.name] = i
        for i, o in enumerate(spec.objects):
            if o.material is not None and o.material not in spec.materials:
                raise SceneError(self.path, f"objects.{i}.material", f"unknown material {o.material!r}")
            obj = SceneObject(o, self.path, i, self.warnings, instancing or spec.render.instancing)
            obj.offset = offset
            obj.face_offset = sum(len(f) for f in faces)
            mat = self.material_names.index(o.material) if o.material else default_material
            if obj.file is not None and o.material is None and obj.file.materials:
                # the file's own materials, per primitive; `material:` overrides them all
                face_mat, obj.file_lookup = self._file_materials(obj.file, i, default_material)
                if obj.instances is not None and not obj.two_level:     # the prototype's, per copy
                    face_mat = np.tile(face_mat, obj.instances.n)
                textured = any(self.materials[m]["texture_index"] >= 0 for m in np.unique(face_mat))
            else:
                face_mat = np.full(len(obj.faces), mat, np.int32)
                textured = self.materials[mat]["texture_index"] >= 0
            any_uv_needed |= textured and obj.uvs is not None
            faces.append(obj.faces + offset)
            mats.append(face_mat)
            uvs.append((obj.uvs, obj.n_vertices))
            offset += obj.n_vertices
            self.objects.append(obj)
        for i, o in enumerate(self.objects):
            for note in (o.usd.notes if o.usd is not None else ()):
                self.warnings.append(f"objects.{i}.mesh: {note}")
        subdivided = [(i, p) for i, o in enumerate(self.objects) if o.usd is not None for p in o.usd.subdivided]
        if subdivided:
            self.warnings.append(f"objects.{subdivided[0][0]}.mesh: {len(subdivided)} USD mesh(es) ask for a "
                                 f"subdivision surface (subdivisionScheme, catmullClark when unset; first: "
                                 f"{subdivided[0][1]}); frustrace renders their polygons as authored")
        if is_usd(self.path):
            plain = [o.name for o in self.objects if o.file is not None and not o.file.materials]
            if plain:
                self.notes.append(f"{len(plain)} mesh(es) without a UsdPreviewSurface material get frustrace's "
                                  f"default material (first: {plain[0]})")
        self.n_vertices = offset
        self.two_level = [o for o in self.objects if o.two_level]
        self._instance_layout()
        self.faces = np.ascontiguousarray(np.concatenate(faces) if faces else np.zeros((0, 3), np.int32), np.int32)
        self.tri_material = np.concatenate(mats) if mats else np.zeros(0, np.int32)
        # UVs only when some textured material has them: no UV work otherwise
        if any_uv_needed:
            self.uvs = np.concatenate([u if u is not None else np.zeros((n, 2), np.float32) for u, n in uvs])
        else:
            self.uvs = np.zeros((0, 2), np.float32)
        self.vertices = np.empty((offset, 3), np.float32)
        for obj in self.objects:                      # static objects: placed once
            if obj.static:
                obj.place(0.0, self.vertices[obj.offset:obj.offset + obj.n_vertices])
        self.moving = [o for o in self.objects if not o.static]
        # rigid movers are placed together (anim/rigid_batch.py), the rest one by one
        rigid = [o for o in self.moving if o.rigid and o.file is None]
        self.rigid_batch = RigidBatch(rigid) if rigid else None
        self.one_by_one = [o for o in self.moving if o not in rigid]
        self._camera_curve = None
        cam = spec.camera
        if cam.keys is not None:
            times = check_times([k.t for k in cam.keys], self.path, "camera.keys", "camera")
            vec = np.array([[k.eye, k.look_at, k.up] for k in cam.keys])   # three points per key
            self._camera_curve = Curve(times, vec, cam.interpolation)
            self._fov_curve = Curve(times, np.array([k.fov for k in cam.keys]), "linear")
        self.outside_paths = self._paths_outside()
        for key, ref in self.outside_paths:
            self.warnings.append(f"{key}: {ref!r} lies outside the scene's directory "
                                 "(it will not travel with the scene; `check --strict` rejects it)")
        self.check_camera(self.frame_numbers)
        if "#" not in spec.output.path and spec.frames.end > spec.frames.start:
            raise SceneError(self.path, "output.path",
                             f"{spec.output.path!r} needs a run of '#' for the frame number: "
                             f"frames {spec.frames.start}..{spec.frames.end} would share one file")
        if not spec.lights:
            self.warnings.append("no lights: surfaces get the ambient term only")
        self._warn_outside_keys()

    def _add_texture(self, material, source, key):
        """Register a material's texture (a path, or (bytes, suffix) from inside
        a file) and set its texture_index; -1 without one (source None)."""
        material["texture_index"] = -1 if source is None else len(self.texture_paths)
        if source is not None:
            self.texture_paths.append(source)
            self.texture_spaces.append(material["texture_space"])
            self.texture_keys.append(key)

    def _file_materials(self, source, index, default_material):
        """Material rows for a glTF or USD object's own materials (appended to
        self.materials, textures registered): ((n_t,) i32 row per triangle,
        the default material where a primitive has none; the row of each
        file slot)."""
        rows = {}
        for m, mat in source.materials.items():
            mat = dict(mat)
            self._add_texture(mat, mat["texture"], f"objects.{index}.mesh")
            rows[m] = len(self.materials)
            self.materials.append(mat)
        lookup = np.full(max(rows) + 2, default_material, np.int32)
        for m, row in rows.items():
            lookup[m] = row
        # -1 (no material) -> the last entry: the default
        return lookup[source.face_material], lookup

    def _paths_outside(self):
        """(key, path) of every file reference that resolves outside the
        scene file's directory (absolute, or climbing out with '..')."""
        spec, base = self.spec, self.path.parent.resolve()
        refs = [(f"materials.{n}.texture", m.texture) for n, m in spec.materials.items() if m.texture]
        for i, o in enumerate(spec.objects):
            if o.mesh:
                refs.append((f"objects.{i}.mesh", o.mesh))
            for j, k in enumerate(o.keyframes or []):
                refs.append((f"objects.{i}.keyframes.{j}.mesh", k.mesh))
            if o.skeleton:
                refs.append((f"objects.{i}.skeleton.weights", o.skeleton.weights))
            if o.instances is not None and o.instances.file:
                refs.append((f"objects.{i}.instances.file", o.instances.file))
        # what a USD or FBX file brings along (sublayers, references, textures) travels with it
        refs += [(f"objects.{i}.mesh", str(f)) for i, o in enumerate(self.objects) if o.fbx is not None
                 for f in o.fbx.texture_files]
        seen = set()
        for i, o in enumerate(spec.objects):
            stage = (base / o.mesh).resolve() if o.mesh and is_usd(o.mesh) else None
            if stage is not None and stage not in seen and stage.is_file():
                seen.add(stage)
                refs += [(f"objects.{i}.mesh", str(dep)) for dep in usd_dependencies(stage) if dep != stage]
        return [(key, ref) for key, ref in refs if not (base / ref).resolve().is_relative_to(base)]

    def check_camera(self, frames):
        """SceneError naming the key if the camera has no viewing direction
        (eye = look_at), or its up vector is zero or parallel to it, at any of
        these frames (every frame of an animated camera; vectorized, in
        blocks, so that a million frames take a second)."""
        keyed = self._camera_curve is not None
        frames = frames if keyed else frames[:1]
        frames = (np.arange(frames.start, frames.stop, frames.step) if isinstance(frames, range)
                  else np.asarray(frames, np.int64))
        with np.errstate(all="ignore"):      # an overflow is judged below, not printed
            self._check_camera_frames(frames, keyed)

    def _check_camera_frames(self, frames, keyed):
        for lo in range(0, len(frames), 1 << 16):
            block = frames[lo:lo + (1 << 16)]
            t = block / self.spec.frames.fps
            if keyed:
                v = self._camera_values(t)                   # (n, 3 points, 3)
                eye, look_at, up = v[:, 0], v[:, 1], v[:, 2]
            else:
                cam = self.spec.camera
                eye, look_at, up = (np.asarray([x], np.float64) for x in (cam.eye, cam.look_at, cam.up))
            forward = look_at - eye
            scale = np.maximum(np.maximum(np.abs(eye).max(axis=1), np.abs(look_at).max(axis=1)), 1e-30)
            length = np.linalg.norm(forward, axis=1)
            no_view = ~(length > 1e-6 * scale)
            up_len = np.linalg.norm(up, axis=1)
            side = np.linalg.norm(np.cross(forward / np.maximum(length, 1e-300)[:, None], up), axis=1)
            no_up = ~no_view & ~((side > 1e-6 * up_len) & (up_len > 0))
            for bad, key, what in ((no_view, "camera.look_at", "look_at equals eye: the camera looks nowhere"),
                                   (no_up, "camera.up", None)):
                if bad.any():
                    i = int(np.argmax(bad))
                    where = f"at frame {int(block[i])} (t = {t[i]:g}): " if keyed else ""
                    what = what or (f"up {tuple(float(u) for u in up[i])} is zero or parallel to the "
                                    "viewing direction (look_at - eye): the image has no 'up'")
                    raise SceneError(self.path, "camera.keys" if keyed else key, where + what)

    def _camera_values(self, t):
        """The keyed camera's (eye, look_at, up) at the times t (n,): the
        camera curve's own cubic segments, evaluated for all t at once
        (clamped outside the keys, as the camera is)."""
        c = self._camera_curve
        if c.coeffs is None:
            return np.broadcast_to(c.values[0], (len(t), *c.values.shape[1:]))
        tc = np.clip(t, c.times[0], c.times[-1])
        k = np.clip(np.searchsorted(c.times, tc, side="right") - 1, 0, len(c.times) - 2)
        s = (tc - c.times[k])[:, None, None]
        co = c.coeffs[k]
        v = ((co[:, 3] * s + co[:, 2]) * s + co[:, 1]) * s + co[:, 0]
        v[tc >= c.times[-1]] = c.values[-1]
        return v

    def _warn_outside_keys(self):
        self.warnings += self.keys_outside(self.spec.frames.start, self.spec.frames.end)

    def keys_outside(self, first, last) -> list:
        """A warning for every keyed motion that frames first..last run past
        (clamped: held still before the first key or after the last), and for
        every USD stage whose time code range they run past."""
        spec = self.spec
        t0, t1 = self.time_of(first), self.time_of(last)
        out = []
        for key, (s0, s1) in self._usd_ranges().items():
            if t0 < s0 - 1e-9 or t1 > s1 + 1e-9:
                out.append(f"{key}: frames {first}..{last} run over t = {t0:g}..{t1:g}, the USD stage's time "
                           f"codes only cover {s0:g}..{s1:g}: its meshes hold their first or last samples outside")
        ranges = []
        if spec.camera.keys:
            ranges.append(("camera.keys", [k.t for k in spec.camera.keys], "clamp"))
        for i, o in enumerate(spec.objects):
            if o.keyframes:
                ranges.append((f"objects.{i}.keyframes", [k.t for k in o.keyframes], o.extrapolate))
            for name in ("translation", "rotation", "scale"):
                track = getattr(o.transform, name, None) if o.transform else None
                if track is not None and track.keys and len(track.keys) > 1:
                    ranges.append((f"objects.{i}.transform.{name}", [r[0] for r in track.keys], o.extrapolate))
        for key, times, extrapolate in ranges:
            if len(times) > 1 and extrapolate == "clamp" and (t0 < min(times) or t1 > max(times)):
                out.append(f"{key}: frames {first}..{last} run over t = {t0:g}..{t1:g}, keys only cover "
                           f"{min(times):g}..{max(times):g}: held still outside")
        return out

    def _usd_ranges(self) -> dict:
        """{key: (t0, t1)} of the USD stages whose meshes move, by the stage's
        authored time code range (one per stage file)."""
        ranges, seen = {}, set()
        for i, o in enumerate(self.objects):
            if o.usd is None or o.static or o.usd.path in seen:
                continue
            seen.add(o.usd.path)
            span = o.usd.time_range()
            if span is not None:
                ranges[f"objects.{i}.mesh"] = span
        return ranges

    def _instance_layout(self):
        """The two-level objects' prototypes and instance ids: each copy's
        triangles numbered as the flattened world would number them (the
        `id` AOV), every other triangle shifted by the copies before it."""
        n_t = sum(len(o.faces) for o in self.objects)
        self.tri_shift = np.zeros(n_t, np.int64)
        self.plain = np.zeros(n_t, bool)
        ranges, moving, protos, id_base, materials, flat = [], [], [], [], [], 0
        for o in self.objects:
            fo, lookup = o.face_offset, getattr(o, "file_lookup", None)
            if o.two_level and o.instances is None and lookup is not None:      # a file's instanced copies
                self.plain[fo:fo + len(o.faces)] = o.file.plain
            blocks = iter(o.blocks() if o.two_level else ())
            size = 0                      # the object's triangles in the flattened world
            for lo, hi, copies, at in o.segments():
                n = hi - lo
                if copies:
                    deforms, slots = next(blocks)
                    id_base.append(flat + at - (fo + lo))
                    protos.append(np.full(copies, len(ranges), np.int32))
                    ranges.append((fo + lo, fo + hi))
                    moving.append(deforms)
                    materials.append(np.full(copies, -1, np.int32) if slots is None or lookup is None
                                     else lookup[slots].astype(np.int32))
                    size += copies * n
                else:
                    self.tri_shift[fo + lo:fo + hi] = flat + at[0] - (fo + lo)
                    size += n
            flat += size
        self.flat_triangles = flat
        self.proto_ranges = np.array(ranges, np.int64).reshape(-1, 2)
        self.proto_moving = np.array(moving, bool)
        self.instance_proto = np.concatenate(protos or [np.zeros(0, np.int32)])
        self.instance_material = np.concatenate(materials or [np.zeros(0, np.int32)])
        self.id_base = np.concatenate(id_base or [np.zeros(0, np.int64)])

    def instances_at(self, t):
        """The two-level objects' instances at time t (raycore/instancing/world.InstanceFrame), or None."""
        if not self.two_level:
            return None
        from raycore.instancing.world import InstanceFrame
        blocks = [m for o in self.two_level for m in o.instance_matrices(t)]
        matrices = blocks[0] if len(blocks) == 1 else np.concatenate(blocks)
        return InstanceFrame(self.proto_ranges, self.proto_moving, self.instance_proto, matrices,
                             self.instance_material, self.id_base, self.tri_shift, self.plain)

    @property
    def world_ranges(self):
        """(first, end) triangle ranges of the moving objects' faces that are
        not two-level prototypes (one tree each in an instanced world)."""
        return [(o.face_offset + lo, o.face_offset + hi) for o in self.moving for lo, hi, copies, _ in o.segments()
                if not copies]

    @property
    def key_bytes(self):
        """Bytes of the vertex keyframes as stored (float32 positions): the
        floor a renderer of them cannot go below."""
        return sum(c.nbytes if hasattr(c, "nbytes") else c.values.size * 4
                   for c in [o.curve for o in self.objects] if c is not None)

    @property
    def moving_triangles(self):
        """Ids of the triangles of moving objects, or None when nothing is
        static (then every frame simply rebuilds everything)."""
        if all(not o.static for o in self.objects):
            return None
        ids = [np.arange(o.face_offset, o.face_offset + len(o.faces)) for o in self.moving]
        return np.concatenate(ids).astype(np.int32) if ids else np.zeros(0, np.int32)

    @property
    def moving_object_ranges(self):
        """(first, end) triangle ranges of the moving objects, one BVH tree each."""
        return [(o.face_offset, o.face_offset + len(o.faces)) for o in self.moving]

    @property
    def frame_numbers(self):
        return range(self.spec.frames.start, self.spec.frames.end + 1)

    def time_of(self, frame):
        return frame / self.spec.frames.fps

    def vertices_at(self, t, held=frozenset()):
        """(n_v, 3) f32 positions at time t; only moving objects are
        recomputed, and of those placed one by one, not the ones in `held`
        (objects held still over a shutter, already in place: see
        held_over). The rigid ones are placed together in one kernel."""
        if self.rigid_batch is not None:
            self.rigid_batch.place(t, self.vertices)
        for obj in self.one_by_one:
            if obj not in held:
                obj.place(t, self.vertices[obj.offset:obj.offset + obj.n_vertices])
        return self.vertices

    def camera_at(self, t):
        """(eye, look_at, up, fov) at time t."""
        cam = self.spec.camera
        if self._camera_curve is None:
            return tuple(cam.eye), tuple(cam.look_at), tuple(cam.up), cam.fov
        v = self._camera_curve(t)
        return tuple(v[0]), tuple(v[1]), tuple(v[2]), float(self._fov_curve(t))

    @property
    def light_table(self):
        """(n, 11) f32 rows for raycore/shading/shade.py: kind (0 point, 1 directional),
        position or direction, colour x intensity, area-light group, and the
        emitting side's unit normal of a one-sided emitter (else 0); an area
        light gives one point row per emitter, each with 1/samples of its
        intensity."""
        rows = []
        for index, light in enumerate(self.spec.lights):
            color = np.asarray(light.color) * light.intensity
            if light.type == "area":
                side = (0.0, 0.0, 0.0)
                if light.sides == 1:
                    n = np.cross(np.asarray(light.edge_u, np.float64), np.asarray(light.edge_v, np.float64))
                    side = tuple(n / np.linalg.norm(n)) if np.linalg.norm(n) > 0 else side
                for p in emitter_positions(light):      # column 7: the area light's group (frame.py)
                    rows.append([0.0, *p, *(color / light.samples), float(index + 1), *side])
                continue
            vec = light.position if light.type == "point" else light.direction
            if light.type == "directional":
                n = np.linalg.norm(vec)
                vec = tuple(np.asarray(vec) / n) if n > 0 else vec
            rows.append([0.0 if light.type == "point" else 1.0, *vec, *color, 0.0, 0.0, 0.0, 0.0])
        return np.asarray(rows, np.float32).reshape(-1, 11)

    @property
    def material_table(self):
        return np.asarray([[*m["diffuse"], m["specular"], m["shininess"], m["texture_index"], 0, 0]
                           for m in self.materials], np.float32)
