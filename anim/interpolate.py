"""Keyframe interpolation as piecewise cubics, evaluated in float64.

Every method is reduced to per-segment coefficients p(t) = c0 + c1 s + c2 s^2
+ c3 s^3 with s = t - t_k, computed once per object, so a frame costs one
Horner evaluation over the values of one segment whatever the method.
* linear       C0, error O(h^2).
* catmull-rom  C1 cubic Hermite; the tangent at a key is the derivative of the
               parabola through it and its neighbours (exact for non-uniform
               key times; at the ends the parabola through the first/last three
               keys), so linear and quadratic motion are reproduced exactly and
               the error is O(h^3).
* cubic        C2 spline, scipy's CubicSpline with not-a-knot ends, O(h^4).
With one key the value is constant; a key's own time returns its value exactly.
"""
import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, Slerp


def _parabola_tangents(times, values):
    """d/dt at each key of the parabola through it and its two neighbours."""
    k = len(times)
    h = np.diff(times)
    slope = np.diff(values, axis=0) / h.reshape(-1, *([1] * (values.ndim - 1)))
    m = np.empty_like(values)
    if k == 2:
        m[0] = m[1] = slope[0]
        return m
    shape = (-1,) + (1,) * (values.ndim - 1)
    h0, h1 = h[:-1].reshape(shape), h[1:].reshape(shape)
    m[1:-1] = (slope[:-1] * h1 + slope[1:] * h0) / (h0 + h1)
    a, b = h[0], h[1]
    m[0] = slope[0] + (slope[0] - slope[1]) * a / (a + b)
    a, b = h[-1], h[-2]
    m[-1] = slope[-1] + (slope[-1] - slope[-2]) * a / (a + b)
    return m


def segment_coeffs(times, values, method):
    """(K-1, 4, ...) float64 coefficients for values (K, ...) at sorted times (K,)."""
    times = np.asarray(times, np.float64)
    values = np.asarray(values, np.float64)
    h = np.diff(times).reshape(-1, *([1] * (values.ndim - 1)))
    p0, p1 = values[:-1], values[1:]
    c = np.zeros((len(times) - 1, 4) + values.shape[1:], np.float64)
    c[:, 0] = p0
    if method == "linear":
        c[:, 1] = (p1 - p0) / h
    elif method == "catmull-rom":
        m = _parabola_tangents(times, values)
        m0, m1 = m[:-1], m[1:]
        slope = (p1 - p0) / h
        c[:, 1] = m0
        c[:, 2] = (3 * slope - 2 * m0 - m1) / h
        c[:, 3] = (m0 + m1 - 2 * slope) / h ** 2
    elif method == "cubic":
        spline = CubicSpline(times, values, axis=0, bc_type="not-a-knot")
        for power in range(4):             # scipy stores the highest power first
            c[:, power] = spline.c[3 - power]
        c[:, 0] = p0
    else:
        raise ValueError(f"unknown interpolation {method!r}")
    return c


def wrap_time(t, t0, t1, extrapolate):
    """Map t into [t0, t1]: clamp, or loop with period t1 - t0."""
    if t1 <= t0:
        return t0
    if extrapolate == "loop":
        return t0 + (t - t0) % (t1 - t0)
    return min(max(t, t0), t1)


class Curve:
    """A keyed value (any shape) with one interpolation method."""

    def __init__(self, times, values, method="linear", extrapolate="clamp"):
        self.times = np.asarray(times, np.float64)
        self.values = np.asarray(values, np.float64)
        self.extrapolate = extrapolate
        self.constant = len(self.times) == 1 or bool(np.all(self.values == self.values[0]))
        self.coeffs = None if len(self.times) == 1 else segment_coeffs(self.times, self.values, method)

    def __call__(self, t):
        if self.coeffs is None:
            return self.values[0]
        t = wrap_time(t, self.times[0], self.times[-1], self.extrapolate)
        if t >= self.times[-1]:
            return self.values[-1]
        k = int(np.searchsorted(self.times, t, side="right")) - 1
        k = min(max(k, 0), len(self.times) - 2)
        s = t - self.times[k]
        c = self.coeffs[k]
        return ((c[3] * s + c[2]) * s + c[1]) * s + c[0]


class RotationCurve:
    """Quaternion keys (w, x, y, z), normalised, slerped along the shortest arc."""

    def __init__(self, times, quats_wxyz, extrapolate="clamp"):
        q = np.asarray(quats_wxyz, np.float64)
        self.times = np.asarray(times, np.float64)
        self.extrapolate = extrapolate
        self.rotations = Rotation.from_quat(q[:, [1, 2, 3, 0]])   # scipy: scalar last
        self.constant = len(self.times) == 1
        self.slerp = None if self.constant else Slerp(self.times, self.rotations)

    def __call__(self, t):
        if self.slerp is None:
            return self.rotations[0].as_matrix()
        t = wrap_time(t, self.times[0], self.times[-1], self.extrapolate)
        return self.slerp([t])[0].as_matrix()
