"""An animated scene: the validated scene file plus everything precomputed to
produce vertex positions at any time.

Work a scene does not need is left out: a static object (one mesh, or one
keyframe, or constant tracks) is placed once; a rigid object costs one 4x4
transform per frame; only deforming objects evaluate per-vertex curves.
"""
from pathlib import Path

import numpy as np
import yaml
from pydantic import ValidationError

from .errors import SceneError
from .interpolate import Curve, RotationCurve
from .mesh_io import load_mesh
from .schema import SceneFile

DEFAULT_MATERIAL = {"diffuse": (0.8, 0.8, 0.8), "specular": 0.0, "shininess": 32.0, "texture": None}


def _key_path(loc):
    return ".".join(str(p) for p in loc)


def read_scene_file(path) -> SceneFile:
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise SceneError(path, "", "file not found") from None
    except OSError as exc:
        raise SceneError(path, "", f"cannot read: {exc.strerror}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise SceneError(path, "", f"invalid YAML{where}: {problem}") from None
    if not isinstance(data, dict):
        raise SceneError(path, "", "top level must be a mapping")
    try:
        return SceneFile.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            msg = "unknown key"
        raise SceneError(path, _key_path(err["loc"]) or "(top)", msg) from None


def _check_times(times, scene_path, key):
    times = np.asarray(times, np.float64)
    for i in range(1, len(times)):
        if not times[i] > times[i - 1]:
            raise SceneError(scene_path, f"{key}.{i}",
                             f"key time {times[i]} is not after the previous one ({times[i - 1]})")
    return times


def _track(track, width, scene_path, key):
    """A translation/scale Curve from rows [t, values...]."""
    rows = track.keys
    if not rows:
        raise SceneError(scene_path, f"{key}.keys", "no keys")
    for i, row in enumerate(rows):
        if len(row) != 1 + width:
            raise SceneError(scene_path, f"{key}.keys.{i}", f"expected {1 + width} numbers (t and {width} values), got {len(row)}")
    arr = np.asarray(rows, np.float64)
    if not np.all(np.isfinite(arr)):
        raise SceneError(scene_path, f"{key}.keys", "non-finite number")
    times = _check_times(arr[:, 0], scene_path, f"{key}.keys")
    return times, arr[:, 1:]


class SceneObject:
    """One object's geometry and motion; `positions(t)` gives (n_v, 3) f32."""

    def __init__(self, spec, scene_path, index):
        base = Path(scene_path).parent
        key = f"objects.{index}"
        self.name = spec.name
        self.extrapolate = spec.extrapolate
        self.curve = None
        self.translation = self.rotation = self.scale = None
        if spec.keyframes is not None:
            times = _check_times([k.t for k in spec.keyframes], scene_path, f"{key}.keyframes")
            meshes = [load_mesh(base / k.mesh, scene_path, f"{key}.keyframes.{i}.mesh")
                      for i, k in enumerate(spec.keyframes)]
            v0, self.faces, self.uvs = meshes[0]
            for i, (v, f, _) in enumerate(meshes[1:], start=1):
                if v.shape != v0.shape or not np.array_equal(f, self.faces):
                    raise SceneError(scene_path, f"{key}.keyframes.{i}.mesh",
                                     f"has {len(v)} vertices / {len(f)} faces, keyframe 0 has "
                                     f"{len(v0)} / {len(self.faces)} (or different faces)")
            self.base = v0
            if len(meshes) > 1:
                stack = np.stack([m[0] for m in meshes])
                self.curve = Curve(times, stack, spec.interpolation, spec.extrapolate)
                if self.curve.constant:
                    self.curve = None
        else:
            self.base, self.faces, self.uvs = load_mesh(base / spec.mesh, scene_path, f"{key}.mesh")
            tr = spec.transform
            if tr is not None:
                if tr.translation is not None:
                    t, v = _track(tr.translation, 3, scene_path, f"{key}.transform.translation")
                    self.translation = Curve(t, v, tr.translation.interpolation, spec.extrapolate)
                if tr.scale is not None:
                    t, v = _track(tr.scale, 3, scene_path, f"{key}.transform.scale")
                    self.scale = Curve(t, v, tr.scale.interpolation, spec.extrapolate)
                if tr.rotation is not None:
                    t, q = _track(tr.rotation, 4, scene_path, f"{key}.transform.rotation")
                    norms = np.linalg.norm(q, axis=1)
                    if np.any(norms < 1e-12):
                        raise SceneError(scene_path, f"{key}.transform.rotation.keys", "zero quaternion")
                    self.rotation = RotationCurve(t, q / norms[:, None], spec.extrapolate)
        self.static = self.curve is None and all(
            c is None or c.constant for c in (self.translation, self.rotation, self.scale))
        self.rigid = self.curve is None

    def positions(self, t):
        if self.curve is not None:
            return self.curve(t).astype(np.float32)
        if self.translation is None and self.rotation is None and self.scale is None:
            return self.base
        s = self.scale(t) if self.scale is not None else np.ones(3)
        r = self.rotation(t) if self.rotation is not None else np.eye(3)
        tr = self.translation(t) if self.translation is not None else np.zeros(3)
        m = r * s[None, :]                              # R @ diag(S)
        return (self.base.astype(np.float64) @ m.T + tr).astype(np.float32)


class AnimatedScene:
    """Loads and checks a scene file; evaluates geometry and camera at time t."""

    def __init__(self, path):
        self.path = Path(path)
        self.spec = read_scene_file(self.path)
        spec = self.spec
        # materials: the file's, plus a default for objects that name none
        self.material_names = list(spec.materials)
        self.materials = [m.model_dump() for m in spec.materials.values()] + [DEFAULT_MATERIAL]
        self.texture_paths = []
        for m in self.materials:
            if m["texture"]:
                tex_path = self.path.parent / m["texture"]
                if not tex_path.is_file():
                    name = self.material_names[self.materials.index(m)]
                    raise SceneError(self.path, f"materials.{name}.texture", f"file not found: {tex_path}")
                m["texture_index"] = len(self.texture_paths)
                self.texture_paths.append(tex_path)
            else:
                m["texture_index"] = -1
        self.objects = []
        offset = 0
        faces, mats, uvs = [], [], []
        any_uv_needed = False
        for i, o in enumerate(spec.objects):
            if o.material is not None and o.material not in spec.materials:
                raise SceneError(self.path, f"objects.{i}.material", f"unknown material {o.material!r}")
            obj = SceneObject(o, self.path, i)
            obj.offset = offset
            mat = self.material_names.index(o.material) if o.material else len(self.material_names)
            textured = self.materials[mat]["texture_index"] >= 0
            any_uv_needed |= textured and obj.uvs is not None
            faces.append(obj.faces + offset)
            mats.append(np.full(len(obj.faces), mat, np.int32))
            uvs.append((obj.uvs, len(obj.base)))
            offset += len(obj.base)
            self.objects.append(obj)
        self.n_vertices = offset
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
                self.vertices[obj.offset:obj.offset + len(obj.base)] = obj.positions(0.0)
        self.moving = [o for o in self.objects if not o.static]
        self._camera_curve = None
        cam = spec.camera
        if cam.keys is not None:
            times = _check_times([k.t for k in cam.keys], self.path, "camera.keys")
            vec = np.array([[*k.eye, *k.look_at, *k.up] for k in cam.keys])
            self._camera_curve = Curve(times, vec, cam.interpolation)
            self._fov_curve = Curve(times, np.array([k.fov for k in cam.keys]), "linear")

    @property
    def frame_numbers(self):
        return list(range(self.spec.frames.start, self.spec.frames.end + 1))

    def time_of(self, frame):
        return frame / self.spec.frames.fps

    def vertices_at(self, t):
        """(n_v, 3) f32 positions at time t; only moving objects are recomputed."""
        for obj in self.moving:
            self.vertices[obj.offset:obj.offset + len(obj.base)] = obj.positions(t)
        return self.vertices

    def camera_at(self, t):
        """(eye, look_at, up, fov) at time t."""
        cam = self.spec.camera
        if self._camera_curve is None:
            return tuple(cam.eye), tuple(cam.look_at), tuple(cam.up), cam.fov
        v = self._camera_curve(t)
        return tuple(v[0:3]), tuple(v[3:6]), tuple(v[6:9]), float(self._fov_curve(t))

    @property
    def light_table(self):
        rows = []
        for light in self.spec.lights:
            vec = light.position if light.type == "point" else light.direction
            if light.type == "directional":
                n = np.linalg.norm(vec)
                vec = tuple(np.asarray(vec) / n) if n > 0 else vec
            color = np.asarray(light.color) * light.intensity
            rows.append([0.0 if light.type == "point" else 1.0, *vec, *color, 0.0])
        return np.asarray(rows, np.float32).reshape(-1, 8)

    @property
    def material_table(self):
        return np.asarray([[*m["diffuse"], m["specular"], m["shininess"], m["texture_index"], 0, 0]
                           for m in self.materials], np.float32)
