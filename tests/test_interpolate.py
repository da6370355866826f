"""Keyframe interpolation: exact keys, exact linear motion, convergence orders."""
import numpy as np
import pytest

from anim.interpolate import Curve, RotationCurve

METHODS = ["linear", "catmull-rom", "cubic"]


@pytest.mark.parametrize("method", METHODS)
def test_keyframes_are_reproduced_exactly(method, rng):
    times = np.cumsum(rng.random(6) + 0.1)
    values = rng.normal(size=(6, 50, 3)).astype(np.float32)
    curve = Curve(times, values, method)
    for t, v in zip(times, values):
        assert np.array_equal(curve(t).astype(np.float32), v)


@pytest.mark.parametrize("method", METHODS)
def test_linear_motion_is_reproduced_by_every_method(method, rng):
    times = np.sort(rng.random(7)) * 3 + np.arange(7)       # uneven spacing
    a, b = rng.normal(size=3), rng.normal(size=3)
    curve = Curve(times, a + times[:, None] * b, method)
    for t in np.linspace(times[0], times[-1], 57):
        np.testing.assert_allclose(curve(t), a + t * b, rtol=0, atol=1e-12)


@pytest.mark.parametrize("method,order", [("linear", 2), ("catmull-rom", 3), ("cubic", 4)])
def test_error_shrinks_at_the_expected_order(method, order):
    def motion(t):
        return np.stack([np.sin(2 * t), np.cos(3 * t), t * t * np.exp(-t)], -1)
    errors = []
    for n in (9, 17, 33, 65):
        times = np.linspace(0, 2, n) + 0.3 * (2 / (n - 1)) * np.sin(np.arange(n))  # non-uniform
        times[0], times[-1] = 0, 2
        curve = Curve(times, motion(times), method)
        ts = np.linspace(0, 2, 1001)
        errors.append(max(np.abs(curve(t) - motion(t)).max() for t in ts))
    rates = -np.diff(np.log(errors)) / np.log(2)
    assert rates[-1] > order - 0.5, f"measured orders {rates}"


def test_one_key_is_static_and_loop_wraps():
    c = Curve([1.0], [[1.0, 2.0, 3.0]])
    assert c.constant and np.array_equal(c(57.0), [1, 2, 3])
    loop = Curve([0.0, 1.0], [[0.0], [1.0]], "linear", "loop")
    assert abs(loop(1.25)[0] - 0.25) < 1e-12
    clamp = Curve([0.0, 1.0], [[0.0], [1.0]], "linear", "clamp")
    assert clamp(-3)[0] == 0 and clamp(3)[0] == 1


def test_slerp_takes_the_short_way_for_antipodal_keys():
    q0 = [1, 0, 0, 0]
    q1 = [-np.cos(0.1), 0, -np.sin(0.1), 0]          # -q of a 0.2 rad turn about y
    rot = RotationCurve([0, 1], [q0, q1])
    m = rot(0.5)
    angle = np.arccos(np.clip((np.trace(m) - 1) / 2, -1, 1))
    assert abs(angle - 0.1) < 1e-9
