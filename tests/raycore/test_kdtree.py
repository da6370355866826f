"""Kd-tree: single-ray and frustum traversal against brute force on random
and adversarial scenes; the projected box-frustum test against an exact
(linear programming) reference; kd-tree frames equal to grid frames."""
import numpy as np
import pytest
from scipy.optimize import linprog

from conftest import icosphere_mesh, soup, tri_verts_of
from oracles import brute_force_closest, camera_rays
from raycore.geometry.camera import camera_basis
from raycore.kdtree.build import LEAF, build_kdtree
from raycore.kdtree.packets import frustum_misses_box, kd_trace_camera
from raycore.kdtree.rays import kd_trace_rays


def _brute(tv, o, d, t_max=None):
    n = len(o)
    t_max = np.full(n, np.inf, np.float32) if t_max is None else t_max
    return brute_force_closest(o.astype(np.float32), d.astype(np.float32), np.zeros(n, np.float32), t_max, tv)[:2]


def _agree(t_a, p_a, t_b, p_b, rtol=1e-5):
    """Same hit or miss, and the same distance on hits."""
    assert np.array_equal(p_a >= 0, p_b >= 0), np.nonzero((p_a >= 0) != (p_b >= 0))[0][:10]
    hit = p_a >= 0
    np.testing.assert_allclose(t_a[hit], t_b[hit], rtol=rtol)


def _grid_aligned(rng):
    """Triangles whose vertices sit on integer coordinates of a 32-cube (every
    SAH bin boundary of the root is a vertex plane), including flat triangles
    lying in such planes."""
    p = rng.integers(0, 33, size=(600, 3, 3)).astype(np.float32)
    flat = p[:200]
    flat[:, :, 2] = flat[:, :1, 2]                      # z = const planes
    return np.ascontiguousarray(p.reshape(-1, 9))


SCENES = {
    "soup": lambda rng: soup(rng, 3000, spread=4.0, size=0.3),
    "grid_aligned": _grid_aligned,
    "sparse": lambda rng: soup(rng, 40, spread=60.0, size=0.5),          # mostly empty leaves
    "dense_cluster": lambda rng: np.concatenate([soup(rng, 4000, spread=0.05, size=0.003),
                                                 soup(rng, 50, spread=8.0, size=0.5)]),
    "sphere": lambda rng: tri_verts_of(*icosphere_mesh(3, 1.0)),
}


@pytest.mark.parametrize("scene", list(SCENES))
def test_single_rays_match_brute_force(scene, rng):
    tv = SCENES[scene](rng)
    deep = scene == "dense_cluster"         # split as far as SAH likes: a very deep tree
    tree = build_kdtree(tv, max_depth=60, c_intersect=1.5, leaf_size=1) if deep else build_kdtree(tv)
    lo, hi = tv.reshape(-1, 3).min(0), tv.reshape(-1, 3).max(0)
    o = rng.uniform(lo - 1, hi + 1, size=(1500, 3)).astype(np.float32)
    d = rng.normal(size=(1500, 3))
    d[:300] = np.eye(3)[rng.integers(0, 3, 300)] * rng.choice([-1, 1], (300, 1))   # parallel to split planes
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    if scene == "grid_aligned":
        o[:300] = np.round(o[:300])                       # rays lying in split planes
    t, p, _, _, _ = kd_trace_rays(tree, tv, o, d)
    bt, bp = _brute(tv, o, d)
    _agree(t, p, bt, bp)
    if scene == "dense_cluster":
        assert tree.depth >= 25


@pytest.mark.parametrize("scene", list(SCENES))
def test_any_hit_agrees_with_brute_force(scene, rng):
    tv = SCENES[scene](rng)
    tree = build_kdtree(tv)
    lo, hi = tv.reshape(-1, 3).min(0), tv.reshape(-1, 3).max(0)
    o = rng.uniform(lo, hi, size=(800, 3)).astype(np.float32)
    d = rng.normal(size=(800, 3)).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t_max = rng.uniform(0.1, 3.0, 800).astype(np.float32)
    _, p, _, _, _ = kd_trace_rays(tree, tv, o, d, t_max=t_max, any_hit=True)
    _, bp = _brute(tv, o, d, t_max)
    assert np.array_equal(p >= 0, bp >= 0)


@pytest.mark.parametrize("scene,eye", [("soup", (0.5, 1.0, 8.0)), ("sphere", (0.2, 0.3, 3.0)),
                                       ("grid_aligned", (16.0, 16.0, 60.0)),   # axis-parallel centre rays
                                       ("soup", (0.1, 0.2, 0.3))])             # camera inside the tree
def test_camera_packets_match_brute_force(scene, eye, rng):
    tv = SCENES[scene](rng)
    tree = build_kdtree(tv)
    w = h = 72                                                               # partial packets at the edges
    target = tv.reshape(-1, 3).mean(0)
    cam = camera_basis(eye, target, [0, 1, 0], 60, w, h)
    t, p, _, _, counters = kd_trace_camera(tree, tv, cam, w, h, 8)
    o, d = camera_rays(cam, w, h)
    bt, bp = _brute(tv, o, d)
    # one shear axis per packet (not per ray): grazing hits agree to ~1e-5
    _agree(t, p, bt, bp, rtol=3e-5)
    assert counters[0] > 0


def _random_frustum(rng):
    """A camera packet frustum: eye, and four corner directions (unnormalised)
    spanning a parallelogram of the image plane."""
    eye = rng.normal(size=3) * 2
    f = rng.normal(size=3)
    r = np.cross(f, rng.normal(size=3))
    u = np.cross(r, f)
    f, r, u = (v / np.linalg.norm(v) for v in (f, r, u))
    u0, v0 = rng.uniform(-0.6, 0.6, 2)
    du, dv = rng.uniform(0.01, 0.5, 2)
    corners = np.array([f + (u0 + a * du) * r + (v0 + b * dv) * u for b in (0, 1) for a in (0, 1)])
    return eye, corners


def _lp_intersects(eye, corners, box):
    """Exact: is there a point eye + sum w_c corner_c (w >= 0) inside box?"""
    a_eq = np.zeros((0, 4))
    a_ub = np.concatenate([corners.T, -corners.T])
    b_ub = np.concatenate([box[3:] - eye, eye - box[:3]])
    res = linprog(np.zeros(4), A_ub=a_ub, b_ub=b_ub, A_eq=a_eq if len(a_eq) else None, bounds=[(0, None)] * 4,
                  method="highs")
    return res.status == 0


def test_projected_box_frustum_test_has_no_false_negatives(rng):
    from numba import njit
    cull = njit(lambda o, fr, box: frustum_misses_box((o[0], o[1], o[2]), fr, box, np.float32(np.inf)))
    culled = kept_empty = 0
    for _ in range(1500):
        eye, corners = _random_frustum(rng)
        fr = np.empty((3, 4), np.float32)
        fr[:, 0] = corners.min(0)
        fr[:, 1] = corners.max(0)
        if not np.all((fr[:, 0] > 0) | (fr[:, 1] < 0)):
            continue                                     # traversal splits such frusta
        inv = 1.0 / fr[:, :2]
        fr[:, 2], fr[:, 3] = inv.min(1), inv.max(1)
        c = eye + rng.normal(size=3) * 3
        half = rng.uniform(0.05, 1.5, 3)
        box = np.concatenate([c - half, c + half]).astype(np.float32)
        exact = _lp_intersects(eye, corners, box)
        misses = cull(eye.astype(np.float32), fr, box)
        assert not (misses and exact), (eye, corners, box)          # never cull a box a ray can hit
        culled += misses
        kept_empty += (not misses) and (not exact)
    assert culled > 100                                  # it does cull


def test_tree_structure_is_consistent(rng):
    tv = soup(rng, 2000)
    tree = build_kdtree(tv)
    inner = tree.axis != LEAF
    assert np.all(tree.child[inner] + 1 < len(tree.axis))
    leaves = ~inner
    assert np.all(tree.child[leaves] + tree.count[leaves] <= len(tree.refs))
    assert set(np.unique(tree.refs[np.concatenate([np.arange(c, c + n) for c, n in
                                                    zip(tree.child[leaves], tree.count[leaves])])])) == set(range(2000))


def test_kdtree_frames_equal_grid_frames(tmp_path):
    from anim import builtin
    from anim.scene import AnimatedScene
    from anim.render.renderer import SceneRenderer
    from anim.render.settings import config_of, shading_of
    scene = AnimatedScene(builtin.get("toys").write(tmp_path / "toys"))
    out = {}
    for accel in ("grid", "kdtree"):
        cfg = config_of(scene, width=96, height=96, accel=accel, packet=16)
        _, out[accel] = SceneRenderer(scene, cfg, shading_of(scene)).render(1.3)
    g, k = out["grid"], out["kdtree"]
    hit_g, hit_k = np.isfinite(g.z), np.isfinite(k.z)
    assert np.array_equal(hit_g, hit_k)
    np.testing.assert_allclose(k.z[hit_g], g.z[hit_g], rtol=1e-5)
    assert np.abs(g.rgba - k.rgba).max() < 1e-2


def test_compare_command_reports_every_structure(tmp_path):
    import json
    from click.testing import CliRunner
    from cli.main import main
    out = tmp_path / "c.json"
    res = CliRunner().invoke(main, ["compare", "grid", "vs", "grid-nocull", "vs", "kdtree", "--scene", "toys",
                                    "--frames", "1", "--res", "64", "--json", str(out)])
    assert res.exit_code == 0, res.output
    report = json.loads(out.read_text())
    rows = {r["structure"]: r for r in report["rows"]}
    assert set(rows) == {"grid", "grid-nocull", "kdtree"}
    # culling and mailboxes cut the grid's ray/triangle tests; images agree
    assert rows["grid-nocull"]["primary_tests"] > 5 * rows["grid"]["primary_tests"]
    for d in report["diff"]:
        assert d["hit_mismatch_pixels"] == 0 and d["max_rel_depth_diff"] < 1e-5, d
    assert CliRunner().invoke(main, ["compare", "grid", "vs", "octree", "--scene", "toys"]).exit_code == 2
    assert CliRunner().invoke(main, ["compare", "grid", "--scene", "toys"]).exit_code == 2


def test_parallel_build_gives_the_same_tree_as_one_thread(rng):
    tv = soup(rng, 25000, spread=6.0, size=0.1)
    one = build_kdtree(tv, threads=1)
    two = build_kdtree(tv, threads=2)
    leaf1, leaf2 = one.axis == LEAF, two.axis == LEAF
    assert len(one.axis) == len(two.axis) and one.depth == two.depth
    assert one.count[leaf1].sum() == two.count[leaf2].sum()
    assert sorted(np.round(one.split[~leaf1], 6)) == sorted(np.round(two.split[~leaf2], 6))
    o = rng.uniform(-4, 4, size=(2000, 3)).astype(np.float32)
    d = rng.normal(size=(2000, 3)).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t1, p1, _, _, _ = kd_trace_rays(one, tv, o, d)
    t2, p2, _, _, _ = kd_trace_rays(two, tv, o, d)
    assert np.array_equal(p1, p2) and np.array_equal(t1, t2)
    bt, bp = _brute(tv, o, d)
    _agree(t2, p2, bt, bp)
