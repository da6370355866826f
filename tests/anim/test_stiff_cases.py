"""Stiff and extreme animation input: near-coincident and uneven key times,
bad key order, bounces, awkward quaternions, huge offsets and tiny scales."""
import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from anim.measure.interp_error import bounce_overshoot
from anim.interpolate import METHODS, Curve, RotationCurve, break_segments
from anim.builtin.authoring import write_obj
from anim.scene import AnimatedScene
from cli.main import main

DENSE = np.linspace(-0.5, 4.5, 5001)


@pytest.mark.parametrize("gap", [1e-9, 1e-12])
@pytest.mark.parametrize("method", METHODS)
def test_keys_1e9_apart_with_a_jump_do_not_blow_up(method, gap):
    times = [0.0, 1.0, 2.0, 2.0 + gap, 3.0, 4.0]
    values = [[0.0], [0.5], [1.0], [-1.0], [-0.5], [0.0]]     # a cut at t = 2
    curve = Curve(times, values, method)
    y = np.array([curve(t)[0] for t in np.concatenate([DENSE, 2.0 + np.linspace(0, gap, 11)])])
    assert np.all(np.isfinite(y))
    assert np.abs(y).max() <= 1.5, np.abs(y).max()
    assert break_segments(np.asarray(times)).tolist() == [False, False, True, False, False]


@pytest.mark.parametrize("method", METHODS)
def test_float32_keys_1e9_apart_on_smooth_motion_stay_accurate(method):
    """Keys stored in float32 (as in OBJ files): the 1e-9 s segment's slope is
    rounding noise / 1e-9 and must not leak into the neighbours."""
    times = np.array([0.0, 0.5, 1.0, 1.0 + 1e-9, 1.5, 2.0, 2.5, 3.0])
    values = np.sin(times + 10.0).astype(np.float32)[:, None] + 1000.0
    values = values.astype(np.float32)
    curve = Curve(times, values, method)
    ts = np.linspace(0, 3, 601)
    err = max(abs(curve(t)[0] - (np.sin(t + 10.0) + 1000.0)) for t in ts)
    limit = 0.2 if method == "clamped" else 0.05      # clamped: at rest at each end of a piece
    assert np.isfinite(err) and err < limit, err


@pytest.mark.parametrize("method", METHODS)
def test_very_uneven_spacing_of_smooth_motion_stays_bounded(method):
    """Spacing ratios up to 1:1600 (not breaks): within a few times the error
    of linear interpolation, and inside the range of the motion."""
    times = np.array([0.0, 1e-3, 2e-3, 0.7, 0.7005, 1.5, 3.0])
    ts = np.linspace(0, 3, 3001)
    y = np.array([Curve(times, np.cos(times)[:, None], method)(t)[0] for t in ts])
    y_lin = np.array([Curve(times, np.cos(times)[:, None], "linear")(t)[0] for t in ts])
    err, err_lin = np.abs(y - np.cos(ts)).max(), np.abs(y_lin - np.cos(ts)).max()
    assert err < 3 * err_lin, (err, err_lin)
    assert -1.2 < y.min() and y.max() < 1.2


def test_pchip_never_goes_through_the_floor_where_smooth_splines_do():
    rows = {(r["method"], r["keys_per_second"]): r for r in bounce_overshoot(keys_per_second=(8, 16))}
    for k in (8, 16):
        assert rows["pchip", k]["min_height"] >= 0
        assert rows["linear", k]["min_height"] >= 0
        for smooth in ("catmull-rom", "cubic", "natural"):
            assert rows[smooth, k]["min_height"] < -1e-3, (smooth, k, rows[smooth, k])


def _angle(m):
    return np.arccos(np.clip((np.trace(m) - 1) / 2, -1, 1))


@pytest.mark.parametrize("method", ["slerp", "spline"])
def test_antipodal_keys_are_the_same_rotation(method):
    q = np.array([0.6, 0.0, 0.8, 0.0])
    rot = RotationCurve([0, 1, 2], [q, -q, q], method)
    assert rot.constant
    ref = Rotation.from_quat(q[[1, 2, 3, 0]]).as_matrix()
    for t in np.linspace(0, 2, 17):
        np.testing.assert_allclose(rot(t), ref, atol=1e-12)


@pytest.mark.parametrize("method", ["slerp", "spline"])
def test_nearly_identical_rotations_do_not_divide_by_zero(method):
    q0 = np.array([1.0, 0, 0, 0])
    q1 = np.array([np.cos(5e-13), np.sin(5e-13), 0, 0])     # 1e-12 rad apart
    rot = RotationCurve([0, 1, 2], [q0, q1, q0], method)
    for t in np.linspace(0, 2, 9):
        m = rot(t)
        assert np.all(np.isfinite(m)) and _angle(m) < 1e-9


@pytest.mark.parametrize("method", ["slerp", "spline"])
def test_half_turn_passes_through_a_quarter_turn(method):
    half = [0.0, 0.0, 1.0, 0.0]                              # 180 degrees about y
    rot = RotationCurve([0, 1], [[1, 0, 0, 0], half], method)
    m = rot(0.5)
    assert np.all(np.isfinite(m))
    assert abs(_angle(m) - np.pi / 2) < 1e-9
    axis = Rotation.from_matrix(m).as_rotvec()
    assert abs(abs(axis[1]) - np.pi / 2) < 1e-9


def _write_scene(tmp_path, objects, mesh=None):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float64) if mesh is None else mesh
    f = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])
    write_obj(tmp_path / "m.obj", v, f)
    path = tmp_path / "s.yaml"
    path.write_text("version: 1\ncamera: {eye: [0, 0, 5], look_at: [0, 0, 0]}\nobjects:\n" + objects)
    return path


def test_non_unit_quaternions_are_normalised_with_a_warning(tmp_path):
    path = _write_scene(tmp_path, """  - name: spinner
    mesh: m.obj
    transform:
      rotation: {keys: [[0, 2, 0, 0, 0], [1, 0, 0, 0, 3]]}
""")
    scene = AnimatedScene(path)
    quaternion = [w for w in scene.warnings if "quaternion" in w]
    assert len(quaternion) == 1 and "key(s) 0, 1 " in quaternion[0], scene.warnings
    v = scene.vertices_at(1.0)
    np.testing.assert_allclose(v[1], [-1, 0, 0], atol=1e-6)   # 180 deg about z
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 0 and "warning" in res.output and "normalised" in res.output


@pytest.mark.parametrize("objects,key", [
    ("""  - name: blob
    keyframes:
      - {t: 0.0, mesh: m.obj}
      - {t: 0.5, mesh: m.obj}
      - {t: 0.5, mesh: m.obj}
""", "objects.0.keyframes.2"),
    ("""  - name: blob
    mesh: m.obj
    transform:
      translation: {keys: [[0, 0, 0, 0], [1, 1, 0, 0], [0.7, 2, 0, 0]]}
""", "objects.0.transform.translation.keys.2"),
])
def test_duplicate_or_decreasing_key_times_exit_2_naming_object_and_key(tmp_path, objects, key):
    path = _write_scene(tmp_path, objects)
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2
    line = res.output.strip()
    assert len(line.splitlines()) == 1 and key in line and "'blob'" in line and "key 2" in line


def _rel_err(got, exact):
    return np.abs(got.astype(np.float64) - exact).max() / np.abs(exact).max()


@pytest.mark.parametrize("offset,scale", [(1e6, 1.0), (0.0, 1e-6), (1e6, 1e-6)])
def test_huge_offsets_and_tiny_scales_keep_float32_relative_precision(tmp_path, offset, scale):
    rng = np.random.default_rng(3)
    base = rng.normal(size=(4, 3))
    k0 = (base * scale + offset).astype(np.float32)
    k1 = ((base + 0.25) * scale + offset).astype(np.float32)
    write_obj(tmp_path / "k0.obj", k0, [[0, 1, 2], [0, 1, 3]])
    write_obj(tmp_path / "k1.obj", k1, [[0, 1, 2], [0, 1, 3]])
    # rigid: a small mesh moved by a translation of `offset` and rotated
    path = _write_scene(tmp_path, f"""  - name: rigid
    mesh: m.obj
    transform:
      translation: {{keys: [[0, {offset}, {offset}, 0], [1, {offset + 3 * scale}, {offset}, 0]]}}
      rotation: {{keys: [[0, 1, 0, 0, 0], [1, 0.8, 0.6, 0, 0]]}}
      scale: {{keys: [[0, {scale}, {scale}, {scale}]]}}
  - name: keyed
    interpolation: linear
    keyframes:
      - {{t: 0, mesh: k0.obj}}
      - {{t: 1, mesh: k1.obj}}
""", mesh=base)
    scene = AnimatedScene(path)
    m = np.asarray(scene.objects[0].base, np.float64)
    keyed = scene.objects[1]                 # the keys as read (float32 -> float64); at 1e6
    k0_file, k1_file = ([np.asarray(keyed.curve.store[k], np.float64) for k in (0, 1)]
                        if keyed.curve is not None                      # a 1e-6 motion is below
                        else [np.asarray(keyed.base, np.float64)] * 2)  # float32's resolution
    for t in (0.0, 0.3, 0.77, 1.0):
        v = scene.vertices_at(t)
        rot = Rotation.from_rotvec([2 * np.arccos(0.8) * t, 0, 0]).as_matrix()
        exact_rigid = (m * scale) @ rot.T + [offset + 3 * scale * t, offset, 0]
        exact_keyed = k0_file + t * (k1_file - k0_file)
        assert _rel_err(v[:4], exact_rigid) < 2 ** -23 * 2
        assert _rel_err(v[4:], exact_keyed) < 2 ** -23 * 2
