"""Keyframe interpolation: exact keys, exact linear motion, measured
convergence orders against the dense analytic motion, extrapolation."""
import numpy as np
import pytest

from anim.measure.interp_error import measure
from anim.interpolate import EXPECTED_ORDER, METHODS, Curve, RotationCurve


@pytest.mark.parametrize("method", METHODS)
def test_keyframes_are_reproduced_exactly(method, rng):
    times = np.cumsum(rng.random(6) + 0.1)
    values = rng.normal(size=(6, 50, 3)).astype(np.float32)
    curve = Curve(times, values, method)
    out = np.empty((50, 3), np.float32)
    for t, v in zip(times, values):
        assert np.array_equal(curve(t).astype(np.float32), v)
        curve.eval_into(t, out)
        assert np.array_equal(out, v)


@pytest.mark.parametrize("method", [m for m in METHODS if m not in ("clamped", "centripetal")])
def test_linear_motion_is_reproduced_on_uneven_keys(method, rng):
    times = np.sort(rng.random(7)) * 3 + np.arange(7)       # uneven spacing
    a, b = rng.normal(size=3), rng.normal(size=3)
    curve = Curve(times, a + times[:, None] * b, method)
    for t in np.linspace(times[0], times[-1], 57):
        np.testing.assert_allclose(curve(t), a + t * b, rtol=0, atol=1e-12)


def test_centripetal_is_exact_for_constant_velocity_on_even_keys(rng):
    times = np.linspace(0, 2, 6)
    a, b = rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    curve = Curve(times, a + times[:, None, None] * b, "centripetal")
    for t in np.linspace(0, 2, 31):
        np.testing.assert_allclose(curve(t), a + t * b, rtol=0, atol=1e-12)


def test_clamped_starts_and_ends_at_rest():
    curve = Curve([0, 1, 2], [[0.0], [1.0], [3.0]], "clamped")
    eps = 1e-6
    assert abs(curve(eps)[0] - curve(0)[0]) < 1e-9
    assert abs(curve(2)[0] - curve(2 - eps)[0]) < 1e-9


def test_eval_into_matches_the_reference_evaluation(rng):
    times = np.cumsum(rng.random(5) + 0.2)
    values = rng.normal(size=(5, 300, 3)) * 1e3
    for method in METHODS:
        curve = Curve(times, values, method)
        out = np.empty((300, 3), np.float32)
        for t in rng.uniform(times[0] - 1, times[-1] + 1, 20):
            curve.eval_into(t, out)
            assert np.array_equal(out, curve(t).astype(np.float32))


@pytest.mark.parametrize("extrapolate", ["clamp", "loop"])
def test_sample_equals_calling_at_each_time(rng, extrapolate):
    """The error studies' vectorised evaluation against the per-call one:
    random times, every key, a hair either side of each, and outside the keys."""
    times = np.cumsum(rng.random(7) + 0.2)
    values = rng.normal(size=(7, 4, 3)) * 1e3
    eps = 1e-12
    ts = np.concatenate([rng.uniform(times[0] - 3, times[-1] + 3, 200), times, times - eps, times + eps])
    for method in METHODS:
        curve = Curve(times, values, method, extrapolate)
        assert np.array_equal(curve.sample(ts), np.stack([curve(t) for t in ts])), method
    one = Curve([1.0], [[1.0, 2.0]], "cubic")
    assert np.array_equal(one.sample([0.0, 5.0]), [[1.0, 2.0], [1.0, 2.0]])


def _sinusoids(rng, n=20):
    a = rng.normal(size=(n, 3))
    w = rng.uniform(1, 3, size=(n, 3))
    ph = rng.uniform(0, 6, size=(n, 3))
    return lambda t: a * np.sin(w * t + ph)


def test_every_method_converges_at_its_expected_order(rng):
    report = measure(_sinusoids(rng), 0.0, 3.0, key_counts=(9, 17, 33, 65, 129))
    for method, o in report["orders"].items():
        # natural / clamped: O(h^4) inside, slower in the boundary layer (see the doc)
        measured = o["measured_interior"] if method in ("natural", "clamped") else o["measured"]
        assert abs(measured - EXPECTED_ORDER[method]) < 0.35, (method, o)
    assert abs(report["orders"]["natural"]["measured"] - 2) < 0.3     # end condition f'' = 0
    assert abs(report["orders"]["clamped"]["measured"] - 1) < 0.3     # end condition f' = 0


def test_error_falls_with_key_density_for_every_method(rng):
    rows = measure(_sinusoids(rng), 0.0, 3.0, key_counts=(9, 17, 33))["rows"]
    for method in METHODS:
        errs = [r["max_err_interior"] for r in rows if r["method"] == method]
        assert errs[0] > errs[1] > errs[2], (method, errs)


@pytest.mark.parametrize("method", METHODS)
def test_one_key_is_static_and_extrapolation_clamps_or_loops(method):
    c = Curve([1.0], [[1.0, 2.0, 3.0]], method)
    assert c.constant and np.array_equal(c(57.0), [1, 2, 3]) and np.array_equal(c(-5.0), [1, 2, 3])
    times, values = [0.0, 0.5, 1.0, 2.0], [[0.0], [2.0], [1.0], [3.0]]
    loop = Curve(times, values, method, "loop")
    for t in (0.3, 0.7, 1.6):
        np.testing.assert_allclose(loop(t + 2.0), loop(t), atol=1e-12)
        np.testing.assert_allclose(loop(t - 4.0), loop(t), atol=1e-12)
    clamp = Curve(times, values, method, "clamp")
    assert clamp(-3)[0] == 0 and clamp(30)[0] == 3


def test_slerp_takes_the_short_way_for_antipodal_keys():
    q0 = [1, 0, 0, 0]
    q1 = [-np.cos(0.1), 0, -np.sin(0.1), 0]          # -q of a 0.2 rad turn about y
    for method in ("slerp", "spline"):
        rot = RotationCurve([0, 1, 2], [q0, q1, q0], method)
        m = rot(0.5)
        angle = np.arccos(np.clip((np.trace(m) - 1) / 2, -1, 1))
        if method == "slerp":
            assert abs(angle - 0.1) < 1e-9
        else:                          # smooth through the turn, never the long way round
            assert 0.05 < angle < 0.2, angle


def test_rotation_spline_converges_faster_than_slerp():
    """A steady tumble about a turning axis: the C2 spline beats slerp."""
    from scipy.spatial.transform import Rotation

    def exact(t):
        return Rotation.from_rotvec(np.stack([np.sin(t), 0.5 * t, np.cos(2 * t) * 0.3], -1))

    errs = {}
    for method in ("slerp", "spline"):
        e = []
        for n in (9, 17, 33):
            times = np.linspace(0, 3, n)
            q = exact(times).as_quat()[:, [3, 0, 1, 2]]
            curve = RotationCurve(times, q, method)
            ts = np.linspace(0.3, 2.7, 97) + 0.0123
            e.append(max((curve.rotation(t) * exact(t).inv()).magnitude() for t in ts))
        errs[method] = e
    slerp_order = np.log2(errs["slerp"][-2] / errs["slerp"][-1])
    spline_order = np.log2(errs["spline"][-2] / errs["spline"][-1])
    assert 1.7 < slerp_order < 2.3 and spline_order > 2.7, (errs, slerp_order, spline_order)


def test_the_one_slerp_matches_scipy_on_random_and_antipodal_pairs():
    from scipy.spatial.transform import Rotation, Slerp
    from anim.track_kernels import slerp_into
    rng = np.random.default_rng(3)
    q = Rotation.random(200, random_state=4).as_quat()[:, [3, 0, 1, 2]]       # w, x, y, z
    out = np.empty(4)
    for i in range(0, 200, 2):
        q0, q1 = q[i], q[i + 1] * (-1 if i % 4 == 0 else 1)                  # half of them antipodal keys
        ref = Slerp([0, 1], Rotation.from_quat(np.stack([q0, q1])[:, [1, 2, 3, 0]]))
        for u in (0.0, 0.3, 0.5, 1.0, rng.random()):
            slerp_into(q0, q1, u, out)
            np.testing.assert_allclose(Rotation.from_quat(out[[1, 2, 3, 0]]).as_matrix(),
                                       ref(u).as_matrix(), atol=1e-9)
    slerp_into(q[0], q[0] * (1 + 1e-13), 0.5, out)                            # nearly equal keys
    np.testing.assert_allclose(out, q[0], atol=1e-12)


def test_relative_angles_match_scipy_and_constant_tracks_are_found_without_it():
    """RotationCurve decides 'constant' with numpy (scipy.spatial is imported
    only when a Python evaluation needs it): the angles are scipy's
    (r0.inv() * r).magnitude(), for random, antipodal and equal keys."""
    from scipy.spatial.transform import Rotation
    from anim.interpolate import relative_angles
    q = Rotation.random(64, random_state=7).as_quat()[:, [3, 0, 1, 2]]
    q[5] = -q[0]                                       # the same rotation as key 0
    q[6] = q[0]
    ref = (Rotation.from_quat(q[[0]][:, [1, 2, 3, 0]]).inv() * Rotation.from_quat(q[:, [1, 2, 3, 0]])).magnitude()
    np.testing.assert_allclose(relative_angles(q[0], q), ref, atol=1e-12)
    assert relative_angles(q[0], q)[[0, 5, 6]].max() == 0.0
    assert RotationCurve([0, 1, 2], [q[0], -q[0], q[0]]).constant
    assert not RotationCurve([0, 1], [q[0], q[1]]).constant
    assert RotationCurve([0], [q[3]]).constant
    with pytest.raises(ValueError, match="unknown rotation interpolation"):
        RotationCurve([0, 1], [q[0], q[1]], "cubic")
