"""Skeletons: joint-angle and quaternion tracks, hierarchy, linear blend
skinning (numba) against a dense evaluation of the analytic joint chain."""
import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from anim.builtin.authoring import write_obj
from anim.scene import AnimatedScene
from cli.main import main


def _arm(tmp_path, extra_object="", weights=None, joints_yaml=None):
    """A strip along x from 0 to 2: shoulder at 0, elbow at 1, hand at 1.5."""
    xs = np.linspace(0, 2, 41)
    verts = np.concatenate([np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], -1),
                            np.stack([xs, np.full_like(xs, 0.1), np.zeros_like(xs)], -1)])
    n = len(xs)
    faces = [[i, i + 1, n + i] for i in range(n - 1)] + [[i + 1, n + i + 1, n + i] for i in range(n - 1)]
    write_obj(tmp_path / "arm.obj", verts, faces)
    x = verts[:, 0]
    if weights is None:
        joint = np.stack([np.where(x < 1, 0, np.where(x < 1.5, 1, 2)), np.where(x < 1, 1, 1)], -1)
        weight = np.stack([np.ones_like(x), np.zeros_like(x)], -1)
        at_elbow = np.abs(x - 1) < 1e-9                       # blended vertices
        joint[at_elbow] = [0, 1]
        weight[at_elbow] = [0.5, 0.5]
        np.savez(tmp_path / "arm_weights.npz", joints=joint, weights=weight)
    joints_yaml = joints_yaml or """        - name: shoulder
          angles: {order: xyz, keys: [[0, 0, 0, 0], [1, 0, 0, 90]]}
        - name: elbow
          parent: shoulder
          origin: [1, 0, 0]
          angles: {order: xyz, keys: [[0, 0, 0, 0], [1, 0, 0, 60]]}
        - name: hand
          parent: elbow
          origin: [1.5, 0, 0]
          rotation: {keys: [[0, 1, 0, 0, 0], [1, 0.8660254037844387, 0.5, 0, 0]]}
"""
    path = tmp_path / "arm.yaml"
    path.write_text(f"""version: 1
camera: {{eye: [0, 0, 6], look_at: [0, 0, 0]}}
objects:
  - name: arm
    mesh: arm.obj
{extra_object}    skeleton:
      weights: arm_weights.npz
      joints:
{joints_yaml}""")
    return path, verts, x


def _oracle(verts, x, t, offset=(0, 0, 0)):
    r1 = Rotation.from_euler("z", 90 * t, degrees=True)
    r2 = Rotation.from_euler("z", 60 * t, degrees=True)
    r3 = Rotation.from_euler("x", 60 * t, degrees=True)      # slerp of a 60 degree turn
    o2, o3 = np.array([1.0, 0, 0]), np.array([1.5, 0, 0])
    shoulder = r1.apply(verts)
    elbow = r1.apply(o2 + r2.apply(verts - o2))
    hand = r1.apply(o2 + r2.apply(o3 - o2 + r3.apply(verts - o3)))
    out = np.where((x < 1)[:, None], shoulder, np.where((x < 1.5)[:, None], elbow, hand))
    blend = np.abs(x - 1) < 1e-9
    out[blend] = 0.5 * shoulder[blend] + 0.5 * elbow[blend]
    return out + np.asarray(offset)


def test_skinned_arm_matches_the_analytic_joint_chain(tmp_path):
    path, verts, x = _arm(tmp_path)
    scene = AnimatedScene(path)
    obj = scene.objects[0]
    assert not obj.static and not obj.rigid
    base = np.asarray(obj.base, np.float64)
    for t in (0.0, 0.25, 0.5, 0.9, 1.0, 2.0):
        got = scene.vertices_at(t)
        want = _oracle(base, x, min(t, 1.0))
        np.testing.assert_allclose(got, want, atol=2e-6)


def test_object_transform_applies_after_skinning(tmp_path):
    path, verts, x = _arm(tmp_path, extra_object="""    transform:
      translation: {keys: [[0, 5, 0, 0], [1, 5, 2, 0]]}
""")
    scene = AnimatedScene(path)
    base = np.asarray(scene.objects[0].base, np.float64)
    np.testing.assert_allclose(scene.vertices_at(0.5), _oracle(base, x, 0.5, (5, 1, 0)), atol=4e-6)


def test_constant_skeleton_is_static(tmp_path):
    path, _, _ = _arm(tmp_path, joints_yaml="""        - name: shoulder
          angles: {keys: [[0, 0, 0, 30]]}
        - {name: elbow, parent: shoulder, origin: [1, 0, 0]}
        - {name: hand, parent: elbow, origin: [1.5, 0, 0]}
""")
    scene = AnimatedScene(path)
    assert scene.objects[0].static and not scene.moving
    rot = Rotation.from_euler("z", 30, degrees=True)
    np.testing.assert_allclose(scene.vertices_at(3.0), rot.apply(scene.objects[0].base), atol=1e-6)


@pytest.mark.parametrize("joints_yaml,key,words", [
    ("""        - {name: elbow, parent: shoulder, origin: [1, 0, 0]}
        - {name: shoulder}
        - {name: hand}
""", "objects.0.skeleton.joints.0.parent", "listed before"),
    ("""        - {name: shoulder}
        - {name: shoulder}
        - {name: hand}
""", "objects.0.skeleton.joints.1.name", "repeats"),
    ("""        - name: shoulder
          angles: {keys: [[0, 0, 0, 0], [0, 0, 0, 90]]}
        - {name: elbow}
        - {name: hand}
""", "objects.0.skeleton.joints.0.angles.keys.1", "key 1"),
])
def test_bad_skeletons_exit_2_naming_the_key(tmp_path, joints_yaml, key, words):
    path, _, _ = _arm(tmp_path, joints_yaml=joints_yaml)
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2 and key in res.output and words in res.output, res.output


def test_bad_weights_exit_2(tmp_path):
    path, verts, _ = _arm(tmp_path)
    np.savez(tmp_path / "arm_weights.npz", joints=np.full((len(verts), 1), 7), weights=np.ones((len(verts), 1)))
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2 and "objects.0.skeleton.weights" in res.output and "0..2" in res.output
    (tmp_path / "arm_weights.npz").unlink()
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2 and "weights file not found" in res.output


def test_lbs_kernel_against_a_python_loop(rng):
    from anim.vertex_kernels import skin_into
    n, j, k = 500, 6, 4
    rest = rng.normal(size=(n, 3)).astype(np.float32) * 100 + 1e4
    joint = rng.integers(0, j, size=(n, k)).astype(np.int32)
    weight = rng.random((n, k)).astype(np.float32)
    weight[rng.random((n, k)) < 0.3] = 0
    weight[:, 0] += 0.01
    weight /= weight.sum(1, keepdims=True)
    mats = rng.normal(size=(j, 3, 4))
    out = np.empty((n, 3), np.float32)
    skin_into(rest, joint, weight, mats, out)
    want = np.zeros((n, 3))
    for v in range(n):
        for c in range(k):
            m = mats[joint[v, c]]
            want[v] += weight[v, c] * (m[:, :3] @ rest[v].astype(np.float64) + m[:, 3])
    np.testing.assert_allclose(out, want, rtol=1e-6, atol=1e-3)


@pytest.mark.parametrize("order", ["xyz", "zyx", "XYZ", "ZXZ", "yxy"])
def test_joint_angles_follow_scipys_euler_convention(tmp_path, order, rng):
    keys = [[0.0, *rng.uniform(-90, 90, 3)], [1.0, *rng.uniform(-90, 90, 3)]]
    joints = f"""        - name: shoulder
          angles: {{order: {order}, keys: {[[float(x) for x in k] for k in keys]}}}
        - name: elbow
          parent: shoulder
          origin: [1, 0, 0]
          rotation: {{interpolation: spline, keys: [[0, 1, 0, 0, 0], [0.5, 0.9, 0.1, 0.3, 0.2], [1, 0.8, 0.0, 0.6, 0]]}}
        - name: hand
          parent: elbow
          origin: [1.5, 0, 0]
          translation: {{keys: [[0, 0, 0, 0], [1, 0.1, 0.2, 0.3]]}}
"""
    path, _, _ = _arm(tmp_path, joints_yaml=joints)
    skel = AnimatedScene(path).objects[0].skeleton
    for t in (0.0, 0.3, 0.77, 1.0):
        # reference: scipy rotations composed down the chain in Python
        ang = np.array(keys[0][1:]) + t * (np.array(keys[1][1:]) - np.array(keys[0][1:]))
        rots = [Rotation.from_euler(order, ang, degrees=True).as_matrix(), skel.rotation[1](t), np.eye(3)]
        origins = np.array([[0, 0, 0], [1, 0, 0], [1.5, 0, 0]], float)
        offsets = [origins[0], origins[1] - origins[0], origins[2] - origins[1] + np.array([0.1, 0.2, 0.3]) * t]
        g_r, g_t, want = np.eye(3), np.zeros(3), []
        for j in range(3):
            g_t = g_r @ offsets[j] + g_t
            g_r = g_r @ rots[j]
            want.append(np.concatenate([g_r, (g_t - g_r @ origins[j])[:, None]], axis=1))
        np.testing.assert_allclose(skel.matrices(t), np.stack(want), atol=1e-12)
