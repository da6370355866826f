"""Many tracks evaluated at once: the curves of many objects (or joints)
packed into flat arrays, and numba kernels that evaluate all of them at one
time t. Same math as anim/interpolate.py (per-segment cubics, clamp/loop,
shortest-arc slerp), float64. Rotation splines stay with scipy (Python).
"""
import numpy as np

from numba import prange

from raycore.jit.presets import kernel, parallel_kernel


def pack_vector_tracks(curves, default):
    """Flat arrays of many translation/scale Curves (None = constant default)."""
    times, coeffs, last, key_start, seg_start, loop = [], [], [], [0], [0], []
    for c in curves:
        if c is None or c.coeffs is None:
            value = np.asarray(default if c is None else c.values[0], np.float64)
            times.append([0.0])
            coeffs.append(np.zeros((0, 4, 3)))
            last.append(value)
        else:
            times.append(c.times)
            coeffs.append(c.coeffs)
            last.append(c.values[-1])
        loop.append(c is not None and c.extrapolate == "loop")
        key_start.append(key_start[-1] + len(times[-1]))
        seg_start.append(seg_start[-1] + len(coeffs[-1]))
    return (np.concatenate(times), np.concatenate(coeffs).reshape(-1, 4, 3), np.array(last),
            np.array(key_start, np.int64), np.array(seg_start, np.int64), np.array(loop))


@kernel
def _segment(times, a, b, t, loop):
    """(k, s, past_end) for time t in keys times[a:b] after clamp/loop;
    past_end (the value is the last key's) also for a single key."""
    t0, t1 = times[a], times[b - 1]
    if t1 <= t0:
        return 0, 0.0, True
    if loop:
        t = t0 + (t - t0) % (t1 - t0)
    t = min(max(t, t0), t1)
    if t >= t1:
        return b - a - 2, t - times[b - 2], True
    lo, hi = a, b - 1                        # times[lo] <= t < times[hi]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if times[mid] <= t:
            lo = mid
        else:
            hi = mid
    return lo - a, t - times[lo], False


@kernel
def eval_vectors(t, times, coeffs, last, key_start, seg_start, loop, out):
    for o in range(out.shape[0]):
        k, s, past_end = _segment(times, key_start[o], key_start[o + 1], t, loop[o])
        if past_end:
            for d in range(3):     # element by element: a row copy compiles numba's
                out[o, d] = last[o, d]   # shape-mismatch message code (~1.5 s)
            continue
        c = coeffs[seg_start[o] + k]
        for d in range(3):
            out[o, d] = ((c[3, d] * s + c[2, d]) * s + c[1, d]) * s + c[0, d]


@kernel
def eval_slerp(t, times, quats, key_start, loop, out):
    """Shortest-arc slerp of unit quaternion keys (w, x, y, z) per object."""
    for o in range(out.shape[0]):
        a, b = key_start[o], key_start[o + 1]
        k, s, past_end = _segment(times, a, b, t, loop[o])
        if past_end:
            for d in range(4):
                out[o, d] = quats[b - 1, d]
            continue
        h = times[a + k + 1] - times[a + k]
        slerp_into(quats[a + k], quats[a + k + 1], s / h, out[o])


@kernel
def slerp_weights(d, u):
    """(w0, w1): the shortest-arc slerp at u in [0, 1] of unit quaternions
    whose dot product is d is w0 q0 + w1 q1 (then normalised). Nearly
    equal keys fall back to a normalised lerp (no division by sin(angle) ~ 0)."""
    sign = 1.0
    if d < 0.0:
        sign, d = -1.0, -d
    if d > 1.0 - 1e-10:
        return 1.0 - u, u * sign
    ang = np.arccos(min(d, 1.0))
    return np.sin((1.0 - u) * ang) / np.sin(ang), sign * np.sin(u * ang) / np.sin(ang)


@kernel
def slerp_into(q0, q1, u, out):
    """The one slerp of unit quaternions (any component order): out = the
    shortest-arc interpolation at u in [0, 1], unit length. Nearly equal keys
    fall back to a normalised lerp (no division by sin(angle) ~ 0)."""
    w0, w1 = slerp_weights(q0[0] * q1[0] + q0[1] * q1[1] + q0[2] * q1[2] + q0[3] * q1[3], u)
    n = 0.0
    for i in range(4):
        out[i] = w0 * q0[i] + w1 * q1[i]
        n += out[i] * out[i]
    n = np.sqrt(n)
    for i in range(4):
        out[i] /= n


@kernel
def quat_to_matrix(w, x, y, z, out):
    """out (3, 3) = rotation of the unit quaternion (w, x, y, z)."""
    out[0, 0], out[0, 1], out[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)
    out[1, 0], out[1, 1], out[1, 2] = 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)
    out[2, 0], out[2, 1], out[2, 2] = 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)


def pack_rotation_tracks(curves):
    """Flat arrays of many RotationCurves (None = identity): (times, quats
    (w, x, y, z), key_start, loop, indices of the `spline` ones, which are
    left to scipy and packed as identity)."""
    times, quats, key_start, loop, python = [], [], [0], [], []
    for i, rot in enumerate(curves):
        if rot is None or rot.method == "spline":
            times.append([0.0])
            quats.append([[1.0, 0.0, 0.0, 0.0]])
            if rot is not None:
                python.append(i)
        else:
            times.append(rot.times)
            quats.append(rot.quats)
        loop.append(rot is not None and rot.extrapolate == "loop")
        key_start.append(key_start[-1] + len(times[-1]))
    return (np.concatenate(times).astype(np.float64), np.concatenate(quats).astype(np.float64),
            np.array(key_start, np.int64), np.array(loop), python)


def tracks_at(t, n, vector_tracks, rotation_track, python_rotations):
    """n objects' (or joints') tracks at time t: a (n, 3) float64 array per
    packed vector track (pack_vector_tracks), the (n, 4) quaternions of the
    packed rotation track (pack_rotation_tracks), and (n, 3, 3) rotation
    matrices, zero but for python_rotations {i: t -> (3, 3)} (rotations a
    packed track cannot hold: scipy splines)."""
    vectors = []
    for packed in vector_tracks:
        out = np.empty((n, 3))
        eval_vectors(t, *packed, out)
        vectors.append(out)
    quat = np.empty((n, 4))
    eval_slerp(t, *rotation_track, quat)
    matrix = np.zeros((n, 3, 3))
    for i, rotation in python_rotations.items():
        matrix[i] = rotation(t)
    return vectors, quat, matrix


@parallel_kernel
def instance_matrices(q0, q1, u, translation, scale, visible, out):
    """out[i] (3, 4) = T + R (S * v) of copy i: its rotation slerped from
    q0[i] to q1[i] at u (as slerp_into), its translation and scale; a
    hidden copy's 3x3 is zero. The instance tables' (anim/instances.py),
    one loop over the copies instead of numpy passes over 100K of them."""
    for i in prange(out.shape[0]):
        a0, a1, a2, a3 = q0[i, 0], q0[i, 1], q0[i, 2], q0[i, 3]
        b0, b1, b2, b3 = q1[i, 0], q1[i, 1], q1[i, 2], q1[i, 3]
        w0, w1 = slerp_weights(a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3, u)
        w, x, y, z = w0 * a0 + w1 * b0, w0 * a1 + w1 * b1, w0 * a2 + w1 * b2, w0 * a3 + w1 * b3
        n = np.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w / n, x / n, y / n, z / n
        rot = ((1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
               (2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
               (2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)))
        shown = 1.0 if visible[i] else 0.0
        for r in range(3):
            for c in range(3):
                out[i, r, c] = rot[r][c] * scale[i, c] * shown
            out[i, r, 3] = translation[i, r]
