"""Interpolation error against run time, measured on a known (analytic) motion.

For each method and keyframe count: keys sampled from the exact motion at
evenly spaced times, the curve evaluated at a quarter, half and three quarters
of every segment, the distance to the exact position taken per vertex. Reported: max and RMS error over the whole key range and over its
interior (the end-condition splines natural/clamped converge slower in a
boundary layer of a few keys), the cost of fitting and of one frame's
evaluation, and the observed convergence order log2(e(2h) / e(h)) of each
halving of the spacing; the order reported per method is that of the finest pair.
"""
import time

import numpy as np

from anim.interpolate import EXPECTED_ORDER, METHODS, Curve

INTERIOR = 0.25         # fraction of the key range left out at each end
# Key ranges start this fraction of the period late, so that evenly spaced keys
# do not land on symmetric points of a motion (e.g. every extremum exactly on a
# key, which flatters pchip).
PHASE = 0.0618


def observed_orders(errors):
    """log2(e(2h) / e(h)) for successive halvings of the key spacing."""
    e = np.maximum(np.asarray(errors, np.float64), 1e-300)
    return [float(x) for x in np.log2(e[:-1] / e[1:])]


def measure(exact, t0, period, key_counts=(5, 9, 17, 33, 65), methods=METHODS, n_timed=32):
    """{'rows': [...], 'orders': {method: {...}}} for exact(t) -> (n, 3) float64.
    key_counts should halve the spacing each step (n -> 2n - 1)."""
    rows = []
    t0 = t0 + PHASE * period
    lo, hi = t0 + INTERIOR * period, t0 + (1 - INTERIOR) * period
    for n_keys in key_counts:
        times = np.linspace(t0, t0 + period, n_keys)
        h = period / (n_keys - 1)
        ts = (times[:-1, None] + h * np.array([0.25, 0.5, 0.75])).reshape(-1)
        inner = (ts > lo) & (ts < hi)
        values = np.stack([exact(t) for t in times])
        truth = [exact(t) for t in ts]
        for method in methods:
            start = time.perf_counter()
            curve = Curve(times, values, method)
            build_ms = (time.perf_counter() - start) * 1e3
            out = np.empty(values.shape[1:], np.float32)
            curve.eval_into(ts[0], out)                # compile / warm
            cost = []
            for t in ts[:: max(1, len(ts) // n_timed)]:
                start = time.perf_counter()
                curve.eval_into(t, out)
                cost.append(time.perf_counter() - start)
            dist = np.stack([np.linalg.norm(curve(t) - ref, axis=-1).reshape(-1) for t, ref in zip(ts, truth)])
            rows.append({"method": method, "keys": n_keys, "spacing": h,
                         "max_err": float(dist.max()), "rms_err": float(np.sqrt(np.mean(dist ** 2))),
                         "max_err_interior": float(dist[inner].max()),
                         "rms_err_interior": float(np.sqrt(np.mean(dist[inner] ** 2))),
                         "build_ms": build_ms, "eval_ms": float(np.median(cost) * 1e3)})
    orders = {}
    for method in methods:
        mine = [r for r in rows if r["method"] == method]
        full = observed_orders([r["max_err"] for r in mine])
        inner = observed_orders([r["max_err_interior"] for r in mine])
        for r, o, oi in zip(mine[1:], full, inner):
            r["order"], r["order_interior"] = o, oi
        orders[method] = {"expected": EXPECTED_ORDER[method], "measured": full[-1] if full else None,
                          "measured_interior": inner[-1] if inner else None}
    return {"rows": rows, "orders": orders}


RESTITUTION = 0.7


def bounce_contacts(n_bounces):
    """Floor contact times of the bouncing ball (flight i lasts RESTITUTION^i s)."""
    return np.concatenate([[0.0], np.cumsum(RESTITUTION ** np.arange(n_bounces))])


def bounce_height(t, n_bounces=4):
    """A ball bouncing on the floor y = 0, peak 1 on the first flight, losing
    speed at each bounce: the velocity jumps at every contact."""
    c = bounce_contacts(n_bounces)
    i = np.clip(np.searchsorted(c, t, side="right") - 1, 0, n_bounces - 1)
    s = np.asarray(t) - c[i]
    return np.maximum(4.0 * s * (RESTITUTION ** i - s), 0.0)   # contact times carry rounding


def bounce_overshoot(methods=METHODS, keys_per_second=(8, 16, 32), n_bounces=4):
    """Per method and key density: the lowest height reached (below 0: through
    the floor) and the max error. Keys are evenly spaced plus one at every
    contact, as an animator or a simulation export would key them."""
    c = bounce_contacts(n_bounces)
    ts = np.linspace(0, c[-1], 8001)
    rows = []
    for k in keys_per_second:
        times = np.union1d(np.arange(0, c[-1], 1.0 / k), c)
        times = times[np.concatenate([[True], np.diff(times) > 1e-9])]
        values = bounce_height(times, n_bounces)[:, None]
        for method in methods:
            curve = Curve(times, values, method)
            y = curve.sample(ts)[:, 0]
            rows.append({"method": method, "keys_per_second": k, "min_height": float(y.min()),
                         "max_err": float(np.abs(y - bounce_height(ts, n_bounces)).max())})
    return rows
