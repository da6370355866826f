"""Instance tables: copies of one object (the prototype, with whatever
motion it has of its own), each placed by its own translation, rotation
(w, x, y, z, slerped along the shortest arc) and scale over time, and
shown or hidden per key (a hidden copy collapses to a point: none of its
triangles can be hit).

A copy's vertex is T + R (S * v) of the prototype's vertex v at the same
time, as a TRS transform places an object. The copies are laid out one
after another (copy i's vertices at i * n_v): the frame's triangles are the
prototype's, repeated."""
from pathlib import Path
import zipfile

import numpy as np

from anim.errors import SceneError
from anim.interpolate import Curve, locate
from anim.track_kernels import instance_matrices
from anim.tracks import FLOAT32_LIMIT, check_times

# render.instancing: auto traces copies two-level (their prototype's tree
# under a top level, raycore/instancing) from TWO_LEVEL_TRIANGLES copied
# triangles on, and from TWO_LEVEL_TRIANGLES_LARGE on when the prototypes
# hold LARGE_PROTOTYPE triangles or more; below, copying them into the
# frame's triangles is as fast or faster (measured, docs/performance.md:
# 100-triangle copies break even at 3.2M, 10,000-triangle ones at ~0.3M)
TWO_LEVEL_TRIANGLES = 3_000_000
TWO_LEVEL_TRIANGLES_LARGE = 1_000_000
LARGE_PROTOTYPE = 1_000


def two_level(instancing, copied, copies):
    """Whether copies totalling `copied` triangles are traced two-level
    under render.instancing = instancing (auto, flatten, two_level)."""
    if instancing != "auto":
        return instancing == "two_level"
    return copied >= TWO_LEVEL_TRIANGLES or (copied >= TWO_LEVEL_TRIANGLES_LARGE
                                             and copied >= LARGE_PROTOTYPE * max(copies, 1))


def quaternion_matrices(q):
    """(n, 3, 3) rotations of unit quaternions q (n, 4) w, x, y, z."""
    w, x, y, z = q.T
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                     np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                     np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], 1)


class LinearTrack:
    """Keyed values (k, ...) interpolated linearly, as a linear Curve (the
    keys exact, clamped or looped) without its per-segment coefficients:
    four times the keys' memory, which a table of many copies feels. Not
    anim/keyframes.LinearKeys: that one holds vertex keys in float32 (and
    may spill them to disk); a copy's translation stays float64, so that a
    copy far from the origin is where its keys put it."""

    def __init__(self, times, values, extrapolate):
        self.times, self.values, self.extrapolate = times, np.asarray(values, np.float64), extrapolate
        self.constant = len(times) == 1 or bool(np.all(self.values == self.values[0]))

    def __call__(self, t):
        if len(self.times) == 1:
            return self.values[0]
        t, k = locate(self.times, t, self.extrapolate)
        if t >= self.times[-1]:
            return self.values[-1]
        u = (t - self.times[k]) / (self.times[k + 1] - self.times[k])
        return self.values[k] + u * (self.values[k + 1] - self.values[k])


def keyed(times, values, method, extrapolate):
    """An instance table's translation or scale keys: a LinearTrack for
    linear interpolation, else a Curve of the method."""
    return LinearTrack(times, values, extrapolate) if method == "linear" else Curve(times, values, method, extrapolate)


class InstanceTable:
    """n copies' TRS keys; `matrices(t)` gives their (n, 3, 4) transforms."""

    def __init__(self, spec, base, scene_path, key, owner, extrapolate):
        self.scene_path, self.key = scene_path, key
        arrays = self._read(spec, base, scene_path, key)
        times = check_times(arrays["t"], scene_path, f"{key}.keys" if spec.keys else f"{key}.file", owner)
        k = len(times)
        tr = arrays["translation"]
        if tr.ndim != 3 or tr.shape[0] != k or tr.shape[2] != 3:
            self._fail(f"translation has shape {tr.shape}; expected ({k}, n, 3)")
        n = tr.shape[1]
        if n == 0:
            self._fail("no instances")
        rot = arrays.get("rotation")
        rot = np.broadcast_to([1.0, 0.0, 0.0, 0.0], (k, n, 4)) if rot is None else rot
        scale = arrays.get("scale")
        given_scale = scale is not None
        scale = np.ones((k, n, 3)) if scale is None else scale
        if scale.ndim == 2 and scale.shape == (k, n):
            scale = np.repeat(scale[:, :, None], 3, axis=2)
        visible = arrays.get("visible")
        visible = np.ones((k, n), bool) if visible is None else visible
        for name, a, shape in (("rotation", rot, (k, n, 4)), ("scale", scale, (k, n, 3)),
                               ("visible", visible, (k, n))):
            if a.shape != shape:
                self._fail(f"{name} has shape {a.shape}; expected {shape} (a row per instance and key, "
                           f"as translation's {n} instances and {k} keys)")
        for name, a in (("translation", tr), ("rotation", rot), ("scale", scale)):
            if not np.all(np.isfinite(a)):
                bad = np.argwhere(~np.isfinite(a))[0]
                self._fail(f"{name}: inf or NaN (key {bad[0]}, instance {bad[1]})")
            if np.abs(a).max() > FLOAT32_LIMIT:
                self._fail(f"{name}: a value beyond {FLOAT32_LIMIT:g}: frames are computed in float32")
        norms = np.linalg.norm(rot, axis=2)
        if np.any(norms < 1e-12):
            bad = np.argwhere(norms < 1e-12)[0]
            self._fail(f"rotation: a zero quaternion (key {bad[0]}, instance {bad[1]})")
        self.n, self.times, self.extrapolate = n, times, extrapolate
        self.quats = rot / norms[:, :, None]
        self.visible = np.asarray(visible, bool)
        self.translation = keyed(times, tr, spec.interpolation, extrapolate)
        # no scale given: none kept (a million copies' ones and their curve cost ~150 MB)
        self.scale = keyed(times, scale, spec.interpolation, extrapolate) if given_scale else None
        self.constant = (self.translation.constant and (self.scale is None or self.scale.constant) and
                         bool(np.all(self.visible == self.visible[0])) and
                         bool(np.all(np.abs(np.sum(self.quats * self.quats[:1], axis=2)) > 1 - 1e-15)))

    def _fail(self, message):
        raise SceneError(self.scene_path, self.key, message)

    def _read(self, spec, base, scene_path, key):
        """{name: float64 array} from the inline keys or the .npz file."""
        if spec.keys is not None:
            keys = spec.keys
            n = len(keys[0].translation)
            out = {"t": np.array([k.t for k in keys], np.float64)}
            for name in ("translation", "rotation", "scale", "visible"):
                rows = [getattr(k, name) for k in keys]
                if all(r is None for r in rows):
                    continue
                for i, r in enumerate(rows):
                    if r is None or len(r) != n:
                        raise SceneError(scene_path, f"{key}.keys.{i}.{name}",
                                         f"{'missing' if r is None else f'{len(r)} rows'}: every key gives "
                                         f"{name} for each of the {n} instances (key 0's translation has {n})")
                if name == "scale":
                    rows = [[s if isinstance(s, (list, tuple)) else (s, s, s) for s in r] for r in rows]
                out[name] = np.asarray(rows, bool if name == "visible" else np.float64)
            return out
        path = Path(base) / spec.file
        if not path.is_file():
            raise SceneError(scene_path, f"{key}.file", f"file not found: {path}")
        try:
            with np.load(path, allow_pickle=False) as data:
                out = {name: np.asarray(data[name]) for name in data.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise SceneError(scene_path, f"{key}.file", f"cannot read {path.name} as .npz: {exc}") from None
        unknown = set(out) - {"t", "translation", "rotation", "scale", "visible"}
        if unknown or "t" not in out or "translation" not in out:
            raise SceneError(scene_path, f"{key}.file", f"{path.name} holds {sorted(out)}; expected t, translation "
                                                        "and optionally rotation, scale, visible")
        for name, a in out.items():
            if name == "visible":
                if a.dtype.kind not in "biu" or (a.dtype.kind != "b" and not np.isin(a, (0, 1)).all()):
                    raise SceneError(scene_path, f"{key}.file", f"{path.name}: visible holds {a.dtype}; expected "
                                                                "true/false (or 0/1) per instance and key")
                out[name] = a.astype(bool)
            elif a.dtype.kind not in "iuf":
                raise SceneError(scene_path, f"{key}.file", f"{path.name}: {name} holds {a.dtype}; expected numbers")
            else:
                out[name] = a.astype(np.float64)
        if out["t"].ndim != 1 or len(out["t"]) == 0:
            raise SceneError(scene_path, f"{key}.file", f"{path.name}: t has shape {out['t'].shape}; expected one "
                                                        "key time or more, (k,)")
        return out

    def matrices(self, t):
        """(n, 3, 4) float64: copy i's T + R (S * v); a hidden copy's collapses to its position."""
        tr = self.translation(t)
        scale = np.ones((self.n, 3)) if self.scale is None else self.scale(t)
        if len(self.times) == 1:
            q0 = q1 = self.quats[0]
            u, vis = 0.0, self.visible[0]
        else:
            t_w, k = locate(self.times, t, self.extrapolate)
            if t_w >= self.times[-1]:
                q0 = q1 = self.quats[-1]
                u, vis = 0.0, self.visible[-1]
            else:                   # visibility holds from the key at or before t
                q0, q1, vis = self.quats[k], self.quats[k + 1], self.visible[k]
                u = (t_w - self.times[k]) / (self.times[k + 1] - self.times[k])
        out = np.empty((self.n, 3, 4))
        instance_matrices(np.ascontiguousarray(q0), np.ascontiguousarray(q1), float(u), np.ascontiguousarray(tr),
                          np.ascontiguousarray(scale), np.ascontiguousarray(vis), out)
        return out
