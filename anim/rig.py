"""Skeletons: a joint hierarchy posed by per-joint tracks, skinned by linear
blend skinning (anim/vertex_kernels.skin_into).

A joint's pose is G_j = G_parent [R_j(t) | o_j - o_parent + T_j(t)]: it turns
about its bind-pose origin o_j, then carries its children. A vertex moves by
sum_k w_k G_j (v - o_j); the per-joint matrices are composed in float64.
"""
from pathlib import Path

import numpy as np

from .errors import SceneError
from .tracks import AngleCurve, rotation_curve, vector_curve


def load_weights(path, n_vertices, n_joints, scene_path, key, warnings):
    """(joint (n, k) int32, weight (n, k) float32, rows summing to 1) from .npz."""
    try:
        with np.load(path) as data:
            joint = np.asarray(data["joints"])
            weight = np.asarray(data["weights"], np.float64)
    except FileNotFoundError:
        raise SceneError(scene_path, key, f"weights file not found: {path}") from None
    except KeyError as exc:
        raise SceneError(scene_path, key, f"{path} lacks the array {exc}; expected 'joints' and 'weights'") from None
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

    def matrices(self, t):
        """(J, 3, 4) float64 skinning matrices at time t."""
        n = len(self.parent)
        pose = np.zeros((n, 3, 4))
        for j in range(n):
            r = self.rotation[j](t) if self.rotation[j] is not None else np.eye(3)
            p = self.parent[j]
            offset = self.origin[j] - (self.origin[p] if p >= 0 else 0.0)
            if self.translation[j] is not None:
                offset = offset + self.translation[j](t)
            if p < 0:
                pose[j, :, :3], pose[j, :, 3] = r, offset
            else:
                pose[j, :, :3] = pose[p, :, :3] @ r
                pose[j, :, 3] = pose[p, :, :3] @ offset + pose[p, :, 3]
        skin = pose.copy()
        skin[:, :, 3] -= np.einsum("jab,jb->ja", pose[:, :, :3], self.origin)   # G_j (v - o_j)
        return skin
