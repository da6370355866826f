"""Skeletons: a joint hierarchy posed by per-joint tracks, skinned by linear
blend skinning (anim/vertex_kernels.skin_into).

A joint's pose is G_j = G_parent [R_j(t) | o_j - o_parent + T_j(t)]: it turns
about its bind-pose origin o_j, then carries its children. A vertex moves by
sum_k w_k G_j (v - o_j); the per-joint matrices are composed in float64.
All joints' tracks are evaluated and composed by numba kernels in one pass
(anim/track_kernels.py); only rotation splines go through scipy.
"""
import zipfile
from pathlib import Path

import numpy as np

from raycore.jit.presets import kernel

from anim.errors import SceneError
from anim.track_kernels import pack_rotation_tracks, pack_vector_tracks, quat_to_matrix, tracks_at
from anim.tracks import AngleCurve, rotation_curve, vector_curve

NO_ROTATION, EULER, QUATERNION, MATRIX = 0, 1, 2, 3


@kernel
def _rotate_about(m, axis, rad):
    """m = m @ R_axis(rad) for a 3x3 float64 matrix, in place."""
    c, s = np.cos(rad), np.sin(rad)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    for r in range(3):
        a, b = m[r, i], m[r, j]
        m[r, i] = a * c + b * s
        m[r, j] = b * c - a * s


@kernel
def _pose(kind, euler, axes, intrinsic, quat, matrix, trans, origin, parent, out):
    """(J, 3, 4) skinning matrices G_j (v - o_j) from evaluated joint tracks."""
    r = np.empty((3, 3))
    g = np.empty((out.shape[0], 3, 4))
    for j in range(out.shape[0]):
        for a in range(3):
            for b in range(3):
                r[a, b] = 1.0 if a == b else 0.0
        if kind[j] == EULER:               # scipy's convention: extrinsic = R2 R1 R0
            for step in range(3):
                k = step if intrinsic[j] else 2 - step
                _rotate_about(r, axes[j, k], np.radians(euler[j, k]))
        elif kind[j] == QUATERNION:
            quat_to_matrix(quat[j, 0], quat[j, 1], quat[j, 2], quat[j, 3], r)
        elif kind[j] == MATRIX:
            for a in range(3):    # element by element: a block copy compiles numba's
                for b in range(3):    # shape-mismatch message (~2 s)
                    r[a, b] = matrix[j, a, b]
        p = parent[j]
        off = np.empty(3)
        for a in range(3):
            off[a] = origin[j, a] - (origin[p, a] if p >= 0 else 0.0) + trans[j, a]
        for a in range(3):
            for b in range(3):
                g[j, a, b] = r[a, b] if p < 0 else (g[p, a, 0] * r[0, b] + g[p, a, 1] * r[1, b]
                                                    + g[p, a, 2] * r[2, b])
            g[j, a, 3] = off[a] if p < 0 else (g[p, a, 0] * off[0] + g[p, a, 1] * off[1]
                                               + g[p, a, 2] * off[2] + g[p, a, 3])
        for a in range(3):
            for b in range(3):
                out[j, a, b] = g[j, a, b]
            out[j, a, 3] = g[j, a, 3] - (g[j, a, 0] * origin[j, 0] + g[j, a, 1] * origin[j, 1]
                                         + g[j, a, 2] * origin[j, 2])


def load_weights(path, n_vertices, n_joints, scene_path, key, warnings):
    """(joint (n, k) int32, weight (n, k) float32, rows summing to 1) from .npz."""
    if not Path(path).is_file():
        raise SceneError(scene_path, key, f"weights file not found: {path}")
    if not zipfile.is_zipfile(path):
        raise SceneError(scene_path, key, f"{path} is not an .npz archive (numpy.savez) with arrays "
                                          "'joints' and 'weights'")
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [name for name in ("joints", "weights") if name not in data.files]
            if missing:
                raise SceneError(scene_path, key, f"{path} has no array {' or '.join(map(repr, missing))} "
                                                  f"(it has: {', '.join(data.files) or 'none'})")
            joint = np.asarray(data["joints"])
            weight = np.asarray(data["weights"], np.float64)
    except SceneError:
        raise
    except Exception as exc:
        raise SceneError(scene_path, key, f"cannot read weights {path}: {exc}") from None
    if joint.ndim == 1:
        joint, weight = joint[:, None], weight[:, None]
    if joint.shape != weight.shape or joint.shape[0] != n_vertices:
        raise SceneError(scene_path, key, f"{path}: joints {joint.shape} and weights {weight.shape} "
                                          f"must both be (n_vertices={n_vertices}, k)")
    if not np.issubdtype(joint.dtype, np.integer) or joint.min() < 0 or joint.max() >= n_joints:
        raise SceneError(scene_path, key, f"{path}: joint indices must be integers in 0..{n_joints - 1}")
    if not np.all(np.isfinite(weight)) or weight.min() < 0:
        raise SceneError(scene_path, key, f"{path}: weights must be finite and >= 0")
    sums = weight.sum(axis=1)
    if np.any(sums <= 0):
        raise SceneError(scene_path, key, f"{path}: vertex {int(np.argmin(sums))} has no weight")
    if np.any(np.abs(sums - 1) > 1e-3):
        warnings.append(f"{scene_path}: {key}: weights of {int(np.sum(np.abs(sums - 1) > 1e-3))} "
                        "vertices did not sum to 1; normalised")
    return np.ascontiguousarray(joint, np.int32), np.ascontiguousarray(weight / sums[:, None], np.float32)


class Skeleton:
    """Joints in file order (a parent before its children) and skin weights."""

    def __init__(self, spec, n_vertices, scene_path, key, owner, extrapolate, warnings):
        names = [j.name for j in spec.joints]
        self.parent = np.full(len(names), -1, np.int64)
        self.origin = np.array([j.origin for j in spec.joints], np.float64)
        self.rotation, self.translation = [], []
        for i, j in enumerate(spec.joints):
            jkey = f"{key}.joints.{i}"
            if names.index(j.name) != i:
                raise SceneError(scene_path, f"{jkey}.name", f"{owner}: joint name {j.name!r} repeats")
            if j.parent is not None:
                if j.parent not in names[:i]:
                    raise SceneError(scene_path, f"{jkey}.parent",
                                     f"{owner}: parent {j.parent!r} must be a joint listed before {j.name!r}")
                self.parent[i] = names.index(j.parent)
            who = f"{owner}, joint {j.name!r}"
            if j.rotation is not None:
                rot = rotation_curve(j.rotation, scene_path, f"{jkey}.rotation", who, extrapolate, warnings)
            elif j.angles is not None:
                rot = AngleCurve(j.angles, scene_path, f"{jkey}.angles", who, extrapolate)
            else:
                rot = None
            self.rotation.append(rot)
            self.translation.append(None if j.translation is None else
                                    vector_curve(j.translation, scene_path, f"{jkey}.translation", who, extrapolate))
        weights_path = Path(scene_path).parent / spec.weights
        self.joint, self.weight = load_weights(weights_path, n_vertices, len(names), scene_path,
                                               f"{key}.weights", warnings)
        self.constant = all(c is None or c.constant for c in self.rotation + self.translation)
        self._pack()

    def _pack(self):
        """Flat arrays of all joints' tracks for the numba kernels."""
        n = len(self.parent)
        self.kind = np.full(n, NO_ROTATION, np.int64)
        self.axes = np.zeros((n, 3), np.int64)
        self.intrinsic = np.zeros(n, np.bool_)
        angle_curves, quat_curves = [None] * n, [None] * n
        for j, rot in enumerate(self.rotation):
            if isinstance(rot, AngleCurve):
                self.kind[j] = EULER
                angle_curves[j] = rot.curve
                self.axes[j] = ["xyz".index(c) for c in rot.order.lower()]
                self.intrinsic[j] = rot.order.isupper()
            elif rot is not None:
                self.kind[j] = MATRIX if rot.method == "spline" else QUATERNION
                quat_curves[j] = rot
        self.packed_angles = pack_vector_tracks(angle_curves, (0.0, 0.0, 0.0))
        *self.packed_quats, self.scipy_joints = pack_rotation_tracks(quat_curves)
        self.packed_trans = pack_vector_tracks(self.translation, (0.0, 0.0, 0.0))

    def matrices(self, t):
        """(J, 3, 4) float64 skinning matrices at time t."""
        n = len(self.parent)
        (euler, trans), quat, matrix = tracks_at(t, n, (self.packed_angles, self.packed_trans), self.packed_quats,
                                                 {j: self.rotation[j] for j in self.scipy_joints})
        out = np.empty((n, 3, 4))
        _pose(self.kind, euler, self.axes, self.intrinsic, quat, matrix, trans, self.origin, self.parent, out)
        return out
