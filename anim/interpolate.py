"""Keyframe interpolation as piecewise cubics, evaluated in float64.

Every method is reduced to per-segment coefficients p(t) = c0 + c1 s + c2 s^2
+ c3 s^3 with s = t - t_k, computed once per track, so a frame costs one
Horner evaluation over one segment whatever the method.

  linear       C0; error O(h^2).
  catmull-rom  C1 Hermite with knots at the key times: the tangent at a key is
               the derivative of the parabola through it and its neighbours
               (Barry-Goldman with t_i as knots; for evenly spaced keys this is
               the uniform Catmull-Rom spline). Exact for quadratic motion; O(h^3).
  centripetal  Catmull-Rom with centripetal knots u_{i+1} - u_i = |P_{i+1} - P_i|^0.5
               per point (no cusps or self-loops along the path), each segment
               mapped affinely onto its time interval. C0 in time; O(h^2).
  cubic        C2 spline, not-a-knot ends (scipy CubicSpline); O(h^4).
  natural      C2 spline, zero second derivative at the ends; O(h^4) inside,
               O(h^2) in a boundary layer of a few keys.
  clamped      C2 spline that starts and ends at rest (zero first derivative):
               ease in / ease out; O(h^4) inside.
  pchip        monotone C1 Hermite (scipy): never overshoots the keys, the
               choice for bounces and holds; O(h^2) (zero slope at extrema).
  akima        Akima (scipy): local, little overshoot; O(h^3) on evenly spaced
               keys, O(h^2) on uneven ones.
  makima       modified Akima (scipy): no overshoot on flat runs.

Hand-written: linear, catmull-rom, centripetal (scipy has none of them).

Stiff input. A segment much shorter than its neighbours (h_k < BREAK_RATIO x the
longer neighbour; e.g. keys 1e-9 s apart, a cut) is a break: it is linear and
the keys on either side are fitted as separate pieces. Otherwise its slope, made
of rounding noise divided by 1e-9, would leak through the tangents of every
smooth method and blow up the neighbouring segments.
"""
import numpy as np

from anim.vertex_kernels import horner_into

METHODS = ("linear", "catmull-rom", "centripetal", "cubic", "natural", "clamped",
           "pchip", "akima", "makima")
ROTATION_METHODS = ("slerp", "spline")     # "linear" is accepted for slerp
# Convergence order of the max error on smooth motion (the interior of the key
# range for the end-condition splines), as theory gives it; bench --error
# prints the measured order next to these.
# pchip drops to 2 at extrema (zero slope there); akima is 3 on evenly spaced
# keys (2 on uneven ones); makima's asymmetric weights make it 2.
EXPECTED_ORDER = {"linear": 2, "catmull-rom": 3, "centripetal": 2, "cubic": 4, "natural": 4,
                  "clamped": 4, "pchip": 2, "akima": 3, "makima": 2}
BREAK_RATIO = 1e-4
_SCIPY_SPLINE_BC = {"cubic": "not-a-knot", "natural": "natural", "clamped": "clamped"}


def _broadcast(h, values):
    """h (K-1,) reshaped to broadcast against values (K-1, ...)."""
    return h.reshape(-1, *([1] * (values.ndim - 1)))


def _parabola_tangents(h, slope):
    """Derivative at each key of the parabola through it and its two neighbours.

    h (K-1, ...) segment lengths (in whatever parameter), broadcastable to
    slope (K-1, ...). The end keys use the parabola through the end three keys.
    """
    m = np.empty((slope.shape[0] + 1,) + slope.shape[1:])
    if slope.shape[0] == 1:
        m[0] = m[1] = slope[0]
        return m
    h0, h1 = h[:-1], h[1:]
    m[1:-1] = (slope[:-1] * h1 + slope[1:] * h0) / (h0 + h1)
    a, b = h[0], h[1]
    m[0] = slope[0] + (slope[0] - slope[1]) * a / (a + b)
    a, b = h[-1], h[-2]
    m[-1] = slope[-1] + (slope[-1] - slope[-2]) * a / (a + b)
    return m


def _hermite(p0, p1, d0, d1, h):
    """Coefficients (K-1, 4, ...) of the cubics with values p and time derivatives d."""
    slope = (p1 - p0) / h
    c = np.empty((p0.shape[0], 4) + p0.shape[1:])
    c[:, 0] = p0
    c[:, 1] = d0
    c[:, 2] = (3 * slope - 2 * d0 - d1) / h
    c[:, 3] = (d0 + d1 - 2 * slope) / (h * h)
    return c


def _centripetal_knot_steps(values):
    """|P_{i+1} - P_i|^0.5 per point (the last axis is a point's coordinates),
    floored so that a point at rest does not divide by zero."""
    diff = np.diff(values, axis=0)
    d = np.linalg.norm(diff, axis=-1) if values.ndim > 1 else np.abs(diff)
    du = np.sqrt(d)
    floor = 1e-9 * du.max(axis=0, keepdims=True) + 1e-300
    du = np.maximum(du, floor)
    return du[..., None] if values.ndim > 1 else du


def _piece_coeffs(times, values, method):
    """Coefficients for one piece (no breaks inside), K >= 2 keys."""
    h = _broadcast(np.diff(times), values)
    p0, p1 = values[:-1], values[1:]
    if method == "linear" or (len(times) == 2 and method not in ("clamped", "centripetal")):
        slope = (p1 - p0) / h
        return _hermite(p0, p1, slope, slope, h)
    if method == "catmull-rom":
        m = _parabola_tangents(h, (p1 - p0) / h)
        return _hermite(p0, p1, m[:-1], m[1:], h)
    if method == "centripetal":
        du = _centripetal_knot_steps(values)
        mu = _parabola_tangents(du, (p1 - p0) / du)      # d/du at each key
        return _hermite(p0, p1, mu[:-1] * du / h, mu[1:] * du / h, h)
    # scipy.interpolate is imported here, by the scenes that use it: its
    # import is ~0.4 s of every start-up otherwise
    from scipy.interpolate import Akima1DInterpolator, CubicSpline, PchipInterpolator
    if method in _SCIPY_SPLINE_BC:
        poly = CubicSpline(times, values, axis=0, bc_type=_SCIPY_SPLINE_BC[method])
    elif method == "pchip":
        poly = PchipInterpolator(times, values, axis=0)
    elif method in ("akima", "makima"):
        poly = Akima1DInterpolator(times, values, axis=0, method=method)
    else:
        raise ValueError(f"unknown interpolation {method!r}")
    c = np.moveaxis(poly.c[::-1], 0, 1).copy()         # scipy: highest power first
    c[:, 0] = p0                                       # keys exact to the last bit
    return c


def break_segments(times):
    """Boolean (K-1,): segments far shorter than a neighbour (see module doc)."""
    h = np.diff(times)
    if len(h) < 2:
        return np.zeros(len(h), bool)
    left = np.concatenate([[0.0], h[:-1]])
    right = np.concatenate([h[1:], [0.0]])
    return h < BREAK_RATIO * np.maximum(left, right)


def pieces(times):
    """[(a, b)]: runs of keys a..b (inclusive) fitted together, and the break
    segments between them (each a (k, k + 1) piece of its own)."""
    brk = break_segments(times)
    out, start = [], 0
    for k, is_break in enumerate(brk):
        if is_break:
            if k > start:
                out.append((start, k))
            out.append((k, k + 1))
            start = k + 1
    if start < len(times) - 1:
        out.append((start, len(times) - 1))
    return out


def segment_coeffs(times, values, method):
    """(K-1, 4, ...) float64 coefficients for values (K, ...) at increasing times (K,)."""
    if method not in METHODS:
        raise ValueError(f"unknown interpolation {method!r}")
    times = np.asarray(times, np.float64)
    values = np.asarray(values, np.float64)
    c = np.empty((len(times) - 1, 4) + values.shape[1:])
    for a, b in pieces(times):
        piece_method = method if b - a > 1 or method == "clamped" else "linear"
        c[a:b] = _piece_coeffs(times[a:b + 1], values[a:b + 1], piece_method)
    return c


def wrap_time(t, t0, t1, extrapolate):
    """Map t into [t0, t1]: clamp, or loop with period t1 - t0."""
    if t1 <= t0:
        return t0
    if extrapolate == "loop":
        return t0 + (t - t0) % (t1 - t0)
    return min(max(t, t0), t1)


def locate(times, t, extrapolate):
    """(t after clamp/loop, index k of the segment [times[k], times[k+1]] holding it)."""
    t = wrap_time(t, times[0], times[-1], extrapolate)
    k = int(np.searchsorted(times, t, side="right")) - 1
    return t, min(max(k, 0), len(times) - 2)


class Curve:
    """A keyed value (any shape) with one interpolation method."""

    def __init__(self, times, values, method="linear", extrapolate="clamp"):
        self.times = np.asarray(times, np.float64)
        self.values = np.asarray(values, np.float64)
        self.method = method
        self.extrapolate = extrapolate
        self.constant = len(self.times) == 1 or bool(np.all(self.values == self.values[0]))
        self.coeffs = None if len(self.times) == 1 else segment_coeffs(self.times, self.values, method)

    def segment(self, t):
        """(k, s): the segment index and the local time of t after extrapolation,
        or (None, None) when t is the last key (returned exactly, not by Horner)."""
        t, k = locate(self.times, t, self.extrapolate)
        if t >= self.times[-1]:
            return None, None
        return k, t - self.times[k]

    def __call__(self, t):
        if self.coeffs is None:
            return self.values[0]
        k, s = self.segment(t)
        if k is None:
            return self.values[-1]
        c = self.coeffs[k]
        return ((c[3] * s + c[2]) * s + c[1]) * s + c[0]

    def sample(self, ts):
        """Values at many times (n, ...), equal to calling the curve at each:
        the same segment, the same Horner steps, the last key returned
        exactly. For dense evaluation (the error studies), where a Python call
        per time cost 7 us."""
        ts = np.asarray(ts, np.float64)
        if self.coeffs is None:
            return np.broadcast_to(self.values[0], ts.shape + self.values.shape[1:]).copy()
        t0, t1 = self.times[0], self.times[-1]
        if self.extrapolate == "loop":
            t = t0 + (ts - t0) % (t1 - t0)
        else:
            t = np.minimum(np.maximum(ts, t0), t1)
        k = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2)
        s = (t - self.times[k]).reshape(t.shape + (1,) * (self.values.ndim - 1))
        c = self.coeffs[k]
        y = ((c[:, 3] * s + c[:, 2]) * s + c[:, 1]) * s + c[:, 0]
        y[t >= t1] = self.values[-1]
        return y

    def eval_into(self, t, out):
        """Write the value at t into `out` (float32, the values' shape) with a
        parallel numba kernel: the per-frame path for vertex keyframes."""
        k, s = (None, None) if self.coeffs is None else self.segment(t)
        if k is None:
            out[...] = self.values[0] if self.coeffs is None else self.values[-1]
            return
        c = self.coeffs[k].reshape(4, -1)
        horner_into(c[0], c[1], c[2], c[3], s, out.reshape(-1))


def relative_angles(q0, q):
    """Angle (radians) of the rotation from unit quaternion q0 to each of q
    (n, 4), all (w, x, y, z): 2 atan2(|v|, |w|) of q0^-1 q, as scipy's
    (r0.inv() * r).magnitude(), without importing scipy.spatial."""
    w0, v0 = q0[0], -np.asarray(q0[1:])
    w, v = q[:, 0], q[:, 1:]
    rw = w0 * w - v @ v0
    rv = w0 * v + w[:, None] * v0 + np.cross(v0, v)
    return 2.0 * np.arctan2(np.linalg.norm(rv, axis=1), np.abs(rw))


def normalized_quaternions(q):
    """(q / |q|, list of the key indices whose |q| was not 1 to 1e-6)."""
    q = np.asarray(q, np.float64)
    norms = np.linalg.norm(q, axis=1)
    if np.any(~(norms > 1e-12)):
        raise ValueError("zero (or non-finite) quaternion")
    off = [int(i) for i in np.nonzero(np.abs(norms - 1) > 1e-6)[0]]
    return q / norms[:, None], off


class RotationCurve:
    """Unit quaternion keys (w, x, y, z). `slerp` along the shortest arc (q and
    -q are the same rotation), or `spline`: scipy's RotationSpline, C2 in the
    rotation vector. Breaks (see module doc) are slerped.

    scipy's rotations are made on the first evaluation here, not at load:
    importing scipy.spatial costs ~0.25 s of every start, and a scene's
    slerped tracks are evaluated by numba kernels (anim/track_kernels.py,
    anim/rigid_batch.py), which need only the keys."""

    def __init__(self, times, quats_wxyz, method="slerp", extrapolate="clamp"):
        q = np.asarray(quats_wxyz, np.float64)
        self.quats = q
        self.times = np.asarray(times, np.float64)
        self.extrapolate = extrapolate
        self.method = "spline" if method == "spline" else "slerp"
        self.constant = len(self.times) == 1 or bool(np.all(relative_angles(q[0], q) < 1e-15))
        if len(self.times) > 1 and method not in ("linear", "slerp", "spline"):
            raise ValueError(f"unknown rotation interpolation {method!r}")
        self._fits = None

    def _pieces(self):
        """scipy's interpolant of each segment (made once, when first asked)."""
        if self._fits is None:
            from scipy.spatial.transform import Rotation, RotationSpline, Slerp
            self.rotations = Rotation.from_quat(self.quats[:, [1, 2, 3, 0]])   # scipy: scalar last
            self._fits = []
            if len(self.times) > 1:
                for a, b in pieces(self.times):
                    span = slice(a, b + 1)
                    if self.method == "spline" and b - a > 1:
                        fit = RotationSpline(self.times[span], self.rotations[span])
                    else:
                        fit = Slerp(self.times[span], self.rotations[span])
                    self._fits += [fit] * (b - a)
        return self._fits

    def rotation(self, t):
        """scipy Rotation at time t."""
        fits = self._pieces()
        if not fits:
            return self.rotations[0]
        t, k = locate(self.times, t, self.extrapolate)
        return fits[k]([t])[0]

    def __call__(self, t):
        return self.rotation(t).as_matrix()
