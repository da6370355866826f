"""Tracks from the scene file turned into curves: translation / scale, rotation
(quaternions) and joint angles, with their checks. Errors name the key path;
quaternions that were not unit length are normalised with a warning."""
import numpy as np

from anim.errors import SceneError
from anim.interpolate import METHODS, Curve, RotationCurve, normalized_quaternions


# largest keyed value accepted: float32 ends at 3.4e38, and a value is still
# multiplied and added (scale times vertex, plus translation) before it is a position
FLOAT32_LIMIT = 1e37


def check_times(times, scene_path, key, owner=""):
    """Key times must increase strictly; names the offending key index."""
    times = np.asarray(times, np.float64)
    who = f"{owner}: " if owner else ""
    for i in range(len(times)):
        if not np.isfinite(times[i]):
            raise SceneError(scene_path, f"{key}.{i}", f"{who}key time is not a finite number")
        if i and not times[i] > times[i - 1]:
            what = "repeats" if times[i] == times[i - 1] else "is before"
            raise SceneError(scene_path, f"{key}.{i}",
                             f"{who}key {i} time {float(times[i])!r} {what} key {i - 1} ({float(times[i - 1])!r}); "
                             "key times must increase")
    return times


def _rows(track, width, scene_path, key, owner):
    rows = track.keys
    if not rows:
        raise SceneError(scene_path, f"{key}.keys", f"{owner}: no keys")
    for i, row in enumerate(rows):
        if len(row) != 1 + width:
            raise SceneError(scene_path, f"{key}.keys.{i}",
                             f"{owner}: expected {1 + width} numbers (t and {width} values), got {len(row)}")
    arr = np.asarray(rows, np.float64)
    if not np.all(np.isfinite(arr)):
        raise SceneError(scene_path, f"{key}.keys", f"{owner}: non-finite number")
    if arr.size and np.abs(arr[:, 1:]).max() > FLOAT32_LIMIT:
        raise SceneError(scene_path, f"{key}.keys", f"{owner}: value {np.abs(arr[:, 1:]).max():g} is "
                                                    f"beyond {FLOAT32_LIMIT:g}: frames are computed in float32")
    return check_times(arr[:, 0], scene_path, f"{key}.keys", owner), arr[:, 1:]


def vector_curve(track, scene_path, key, owner, extrapolate):
    """A translation or scale track: rows [t, x, y, z]."""
    if track.interpolation not in METHODS:
        raise SceneError(scene_path, f"{key}.interpolation",
                         f"{owner}: {track.interpolation!r} is for rotation tracks; use one of {', '.join(METHODS)}")
    times, values = _rows(track, 3, scene_path, key, owner)
    return Curve(times, values, track.interpolation, extrapolate)


def rotation_curve(track, scene_path, key, owner, extrapolate, warnings):
    """A rotation track: rows [t, w, x, y, z]; slerp (= linear) or spline."""
    if track.interpolation not in ("linear", "slerp", "spline"):
        raise SceneError(scene_path, f"{key}.interpolation",
                         f"{owner}: rotation tracks take slerp (or linear) or spline, not {track.interpolation!r}")
    times, q = _rows(track, 4, scene_path, key, owner)
    try:
        q, off = normalized_quaternions(q)
    except ValueError as exc:
        raise SceneError(scene_path, f"{key}.keys", f"{owner}: {exc}") from None
    if off:
        warnings.append(f"{scene_path}: {key}.keys: {owner}: quaternion(s) at key(s) "
                        f"{', '.join(map(str, off))} were not unit length; normalised")
    return RotationCurve(times, q, track.interpolation, extrapolate)


class AngleCurve:
    """Joint angles (degrees) interpolated per axis, turned into a rotation."""

    def __init__(self, track, scene_path, key, owner, extrapolate):
        times, values = _rows(track, 3, scene_path, key, owner)
        self.order = track.order
        self.curve = Curve(times, values, track.interpolation, extrapolate)
        self.constant = self.curve.constant

    def __call__(self, t):
        from scipy.spatial.transform import Rotation      # lazily: see anim/interpolate.py
        return Rotation.from_euler(self.order, self.curve(t), degrees=True).as_matrix()


def trs_matrix(translation, rotation, scale, t):
    """(3, 4) float64 matrix T + R (S * v) from optional curves at time t."""
    m = np.zeros((3, 4))
    r = rotation(t) if rotation is not None else np.eye(3)
    s = scale(t) if scale is not None else np.ones(3)
    m[:, :3] = r * s[None, :]
    if translation is not None:
        m[:, 3] = translation(t)
    return m


def compose(a, b):
    """a @ b for (3, 4) affine matrices (or b of shape (..., 3, 4))."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., :3] = a[:, :3] @ b[..., :3]
    out[..., 3] = (a[:, :3] @ b[..., 3, None])[..., 0] + a[:, 3]
    return out
