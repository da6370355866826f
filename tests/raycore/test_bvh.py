"""The per-frame BVH (raycore/bvh/build.py, bvh/trace.py, bvh/scene.py)
against brute force: every packet mode (rays sharing an origin, rays
sharing a direction, rays one by one) on adversarial rays, shadow rays
as the frame makes them, trees refit to moving vertices and rebuilt when
their cost has grown, and the extreme cases of the grid's tests."""
import numpy as np
import pytest

from conftest import icosphere_mesh, soup, tri_verts_of
from oracles import brute_force_closest
from raycore.accelerators import BvhAccel, GridAccel
from raycore.bvh.build import sah_cost
from raycore.bvh.trace import SHARED_DIRECTION, SHARED_ORIGIN, SINGLE, bvh_trace_rays
from raycore.geometry.camera import camera_basis
from raycore.grid.build import build_grid
from raycore.bvh.scene import REBUILD_GROWTH, SceneBvh
from raycore.geometry.light_rays import LightRays
from raycore.grid.trace import trace_camera
from raycore.shading.visibility import surface_of

MODES = {"shared origin": SHARED_ORIGIN, "shared direction": SHARED_DIRECTION, "single": SINGLE}


def _scene(rng):
    v, f = icosphere_mesh(2, 1.0)
    floor = np.array([[-4, -1.5, -4, 4, -1.5, -4, 4, -1.5, 4], [-4, -1.5, -4, 4, -1.5, 4, -4, -1.5, 4]],
                     np.float32)
    return np.ascontiguousarray(np.concatenate([tri_verts_of(v, f), soup(rng, 400, spread=5.0, size=0.3), floor]))


def _edge(hit, b1, b2):
    """Hits within 1e-4 (barycentric) of an edge or corner of their triangle
    (a miss's barycentrics are whatever its buffer held: no warning on them)."""
    with np.errstate(invalid="ignore", over="ignore"):
        return hit & (np.minimum(np.minimum(b1, b2), 1 - b1 - b2) < 1e-4)


def _agree(got, want, tv):
    """Same hit or miss and distance, but where a ray grazes an edge or
    corner, by the barycentrics of either hit (rays aimed at the vertices of
    open triangles: either answer is right to float32 precision)."""
    t, prim, b1, b2 = got[:4]
    w_t, w_prim, w_b1, w_b2 = want
    grazing = _edge(prim >= 0, b1, b2) | _edge(w_prim >= 0, w_b1, w_b2)
    differ = (prim >= 0) != (w_prim >= 0)
    assert not np.any(differ & ~grazing), np.nonzero(differ & ~grazing)[0][:10]
    both = (prim >= 0) & (w_prim >= 0)
    ok = np.isclose(t[both], w_t[both], rtol=2e-5, atol=1e-6) | grazing[both]
    assert np.all(ok), np.nonzero(both)[0][~ok][:10]


def _adversarial_dirs(rng, tv, origin_of, n=800):
    """Directions: random; axis-parallel of both signs; with a zero component;
    through vertices and edge midpoints of random triangles."""
    d = rng.normal(size=(n, 3)).astype(np.float32)
    d[:100] = 0
    d[np.arange(100), rng.integers(0, 3, 100)] = rng.choice([-1.0, 1.0], 100)
    d[100:200, rng.integers(0, 3)] = 0
    corners = tv[rng.integers(0, len(tv), 200)].reshape(-1, 3, 3)
    d[200:400] = corners[:, 0] - origin_of(slice(200, 400))
    d[400:600] = 0.5 * (corners[:, 0] + corners[:, 1]) - origin_of(slice(400, 600))
    return np.ascontiguousarray(d / np.linalg.norm(d, axis=1, keepdims=True), np.float32)


@pytest.mark.parametrize("mode", list(MODES))
@pytest.mark.parametrize("any_hit", [False, True])
def test_every_packet_mode_matches_brute_force(rng, mode, any_hit):
    tv = _scene(rng)
    bvh = SceneBvh.of_objects(len(tv), [(0, 320)]).update(tv)
    n = 800
    if mode == "shared direction":
        # parallel rays from many origins: one direction, axis-parallel, then a random one
        for d0 in (np.array([0, -1, 0], np.float32), rng.normal(size=3).astype(np.float32)):
            d0 /= np.linalg.norm(d0)
            o = rng.uniform(-3, 3, (n, 3)).astype(np.float32)
            o[:200] = tv[rng.integers(0, len(tv), 200), :3] - 2 * d0       # aimed at vertices
            d = np.ascontiguousarray(np.broadcast_to(d0, (n, 3)))
            _check(bvh, tv, o, d, any_hit, MODES[mode])
        return
    if mode == "shared origin":
        for eye in ((0.2, 0.1, 0.3), (0.0, 6.0, 2.0)):            # inside the sphere, and outside everything
            o = np.ascontiguousarray(np.broadcast_to(np.array(eye, np.float32), (n, 3)))
            _check(bvh, tv, o, _adversarial_dirs(rng, tv, lambda s: o[s]), any_hit, MODES[mode])
        return
    o = rng.uniform(-2.5, 2.5, (n, 3)).astype(np.float32)
    _check(bvh, tv, o, _adversarial_dirs(rng, tv, lambda s: o[s]), any_hit, MODES[mode])


@pytest.mark.parametrize("any_hit", [False, True])
def test_ragged_packets_and_partly_live_chunks_match_brute_force(rng, any_hit):
    """Packets whose last 16-ray chunk is part filled (n not a multiple of
    16, the pad rays must never hit), and packets where some chunks' rays
    are all dead or miss a node that others enter (the chunk masks)."""
    tv = _scene(rng)
    bvh = SceneBvh.of_objects(len(tv), [(0, 320)]).update(tv)
    o800 = np.ascontiguousarray(np.broadcast_to(np.array((0.0, 6.0, 2.0), np.float32), (800, 3)))
    for n in (1, 5, 17, 100, 127, 133, 261):
        d = np.ascontiguousarray(_adversarial_dirs(rng, tv, lambda s: o800[s])[rng.permutation(800)[:n]])
        _check(bvh, tv, o800[:n], d, any_hit, SHARED_ORIGIN)
    # every other chunk of each packet dead (t_max < t_min): they find
    # nothing, and the live rays beside them what brute force finds
    n = 512
    o = np.ascontiguousarray(np.broadcast_to(np.array((0.2, 0.1, 0.3), np.float32), (800, 3)))
    d = _adversarial_dirs(rng, tv, lambda s: o[s])[rng.permutation(800)[:n]]
    o = o[:n]
    dead = (np.arange(n) // 16) % 2 == 1
    t_max = np.where(dead, -1.0, np.inf).astype(np.float32)
    got = bvh_trace_rays(bvh, o, np.ascontiguousarray(d), t_max=t_max, any_hit=any_hit, mode=SHARED_ORIGIN)
    assert np.all(got[1][dead] == -1)
    live = ~dead
    want = brute_force_closest(o[live], d[live], np.zeros(live.sum(), np.float32),
                               np.full(live.sum(), np.inf, np.float32), tv)
    got = tuple(a[live] for a in got[:4])
    if not any_hit:
        _agree(got, want, tv)
    else:
        edge = _edge(got[1] >= 0, got[2], got[3]) | _edge(want[1] >= 0, want[2], want[3])
        assert not np.any(((got[1] >= 0) != (want[1] >= 0)) & ~edge)


def _check(bvh, tv, o, d, any_hit, mode):
    n = len(o)
    t_min = np.zeros(n, np.float32)
    t_max = np.full(n, np.inf, np.float32)
    want = brute_force_closest(o, d, t_min, t_max, tv)
    got = bvh_trace_rays(bvh, o, d, any_hit=any_hit, mode=mode)
    if not any_hit:
        _agree(got, want, tv)
        return
    # any hit: hit or miss as brute force, but for grazes
    edge = _edge(got[1] >= 0, got[2], got[3]) | _edge(want[1] >= 0, want[2], want[3])
    assert not np.any(((got[1] >= 0) != (want[1] >= 0)) & ~edge)
    # cut short before the closest hit: brute force and the tree agree
    short = np.where(want[1] >= 0, want[0] * 0.9, np.inf).astype(np.float32)
    got = bvh_trace_rays(bvh, o, d, t_max=short, any_hit=True, mode=mode)
    want = brute_force_closest(o, d, t_min, short, tv)
    edge = _edge(got[1] >= 0, got[2], got[3]) | _edge(want[1] >= 0, want[2], want[3])
    assert not np.any(((got[1] >= 0) != (want[1] >= 0)) & ~edge)


def test_packets_are_watertight_through_shared_vertices_and_edges():
    """Rays from one point through every vertex and edge midpoint of a closed
    sphere from inside: each hits (no ray slips between two triangles)."""
    v, f = icosphere_mesh(3, 1.0)
    tv = tri_verts_of(v, f)
    bvh = SceneBvh.of_objects(len(tv)).update(tv)
    targets = np.concatenate([v, 0.5 * (v[f[:, 0]] + v[f[:, 1]])]).astype(np.float64)
    for eye in ((0.0, 0.0, 0.0), (0.1, -0.2, 0.05)):
        d = targets - np.array(eye)
        d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
        o = np.ascontiguousarray(np.broadcast_to(np.array(eye, np.float32), d.shape))
        for mode in (SHARED_ORIGIN, SINGLE):
            got = bvh_trace_rays(bvh, o, d, mode=mode)
            assert np.all(got[1] >= 0), (eye, mode, np.sum(got[1] < 0))


def _tree_is_consistent(trees, tv):
    """Every reachable node's box holds its children's boxes or its triangles,
    a leaf's copied corners are the triangles', every triangle is in one leaf."""
    b = trees.bvh
    seen = np.zeros(len(tv), int)
    stack = [0]
    while stack:
        i = stack.pop()
        if b.count[i] > 0:
            refs = np.arange(b.child[i], b.child[i] + b.count[i])
            np.testing.assert_array_equal(b.verts[refs], tv[b.tri[refs]])
            corners = tv[b.tri[refs]].reshape(-1, 3)
            assert np.all(corners >= b.box[i, :3]) and np.all(corners <= b.box[i, 3:])
            seen[b.tri[refs]] += 1
        elif b.child[i] >= 0:          # inner (count -1 - axis)
            for c in (b.child[i], b.child[i] + 1):
                assert np.all(b.box[c, :3] >= b.box[i, :3]) and np.all(b.box[c, 3:] <= b.box[i, 3:])
                stack.append(c)
    np.testing.assert_array_equal(seen, 1)


def test_refit_follows_deforming_and_rigid_motion(rng):
    """A deforming sphere, a rigidly moving soup and a static floor: after
    each refit, the tree is consistent and rays agree with brute force; the
    static tree's nodes never change."""
    tv0 = _scene(rng)
    n_sphere, n_soup = 320, 400
    trees = SceneBvh.of_objects(len(tv0), [(0, n_sphere), (n_sphere, n_sphere + n_soup)])
    static_node = int(trees.node_lo[-1])
    tv = tv0.copy()
    trees.update(tv)
    static_box = trees.bvh.box[static_node].copy()
    o = np.ascontiguousarray(np.broadcast_to(np.array([0.3, 5.0, 4.0], np.float32), (600, 3)))
    for step in range(1, 4):
        wobble = (0.1 * np.sin(step + np.arange(n_sphere * 3))).astype(np.float32)
        tv[:n_sphere] = tv0[:n_sphere] * (1 + np.repeat(wobble.reshape(n_sphere, 3), 3, axis=1))
        tv[n_sphere:n_sphere + n_soup] = tv0[n_sphere:n_sphere + n_soup] + np.float32(0.4 * step)
        bvh = trees.update(tv)
        assert trees.stats["bvh_rebuilt"] == 0
        _tree_is_consistent(trees, tv)
        np.testing.assert_array_equal(trees.bvh.box[static_node], static_box)
        d = _adversarial_dirs(rng, tv, lambda s: o[s], 600)
        want = brute_force_closest(o, d, np.zeros(600, np.float32), np.full(600, np.inf, np.float32), tv)
        _agree(bvh_trace_rays(bvh, o, d, mode=SHARED_ORIGIN), want, tv)


def test_a_mesh_refits_from_its_shared_vertices_as_a_soup_does(rng):
    """A mesh's trees refit from its vertex array through each reference's
    faces (SceneBvh(faces=...), as a render does): boxes, leaf-order corners
    and SAH costs equal those of the same triangles refit as a soup, bit for
    bit, over a deforming icosphere with a moving second copy; and a tree
    made with faces refuses a refit without the vertices."""
    v0, f = icosphere_mesh(3)
    faces = np.concatenate([f, f + len(v0)])
    n = len(faces)
    mesh = SceneBvh.of_objects(n, [(0, len(f)), (len(f), n)], faces=faces)
    as_soup = SceneBvh.of_objects(n, [(0, len(f)), (len(f), n)])
    for step in range(4):
        bend = np.float32(1) + np.float32(0.2) * np.sin(step + 3 * v0[:, :1]).astype(np.float32)
        vertices = np.ascontiguousarray(np.concatenate([v0 * bend, v0 + np.float32(0.5 * step)]), np.float32)
        tv = tri_verts_of(vertices, faces)
        a, b = mesh.update(tv, vertices), as_soup.update(tv)
        assert mesh.stats["bvh_rebuilt"] == as_soup.stats["bvh_rebuilt"] == (2 if step == 0 else 0)   # refits after the first
        reached = _reachable(a)
        assert reached == _reachable(b)
        np.testing.assert_array_equal(a.node.view(np.int32)[reached], b.node.view(np.int32)[reached])
        np.testing.assert_array_equal(a.verts, b.verts)
        np.testing.assert_array_equal(mesh.cost, as_soup.cost)
        np.testing.assert_array_equal(a.verts, tv[a.tri])
    with pytest.raises(ValueError, match="vertices"):
        mesh.update(tv)


def test_a_tree_whose_parts_scatter_is_rebuilt(rng):
    """Triangles that swap places make a refit tree's boxes overlap: its SAH
    cost grows past REBUILD_GROWTH and the next update rebuilds it, after
    which its cost is that of a fresh build."""
    tv0 = np.ascontiguousarray(soup(rng, 2000, spread=4.0, size=0.1))
    trees = SceneBvh.of_objects(len(tv0))
    trees.update(tv0)
    built = float(trees.built_cost[0])
    tv = np.ascontiguousarray(tv0[rng.permutation(len(tv0))])     # every triangle elsewhere
    trees.update(tv)
    assert trees.stats["bvh_rebuilt"] == 1
    assert trees.stats["bvh_sah_growth"] > REBUILD_GROWTH
    b = trees.bvh
    assert abs(float(trees.cost[0]) - sah_cost(b.box, b.child, b.count, int(trees.node_lo[0]))) < 1e-3 * built
    _tree_is_consistent(trees, tv)
    # moving by a little keeps the tree
    trees.update(tv + np.float32(1e-3))
    assert trees.stats["bvh_rebuilt"] == 0


@pytest.mark.parametrize("kind", [0, 1])
def test_shadow_rays_see_what_the_grid_sees(rng, kind):
    """The frame's shadow rays (LightRays, light-space order) through the BVH
    and through the grid: the same visibility, but for rays that graze an
    occluder's edge within float32 rounding (checked against brute force).
    The BVH's own path (trace_lights: the rays made in its packets, in the
    samples' order, the inactive ones dead) sees what it sees in
    light-space order, but for such grazes; skipped samples get 0, and
    lights traced together see what each sees alone."""
    tv = np.ascontiguousarray(np.concatenate([
        soup(rng, 1500, spread=3.0, size=0.3),
        np.array([[-4, -2, -4, 4, -2, -4, 0, -2, 4], [-4, -2, 4, 4, -2, 4, 0, -2, -4]], np.float32)]))
    grid = build_grid(tv)
    w = h = 64
    cam = camera_basis([0.5, 4.0, 7.0], [0, -1, 0], [0, 1, 0], 50, w, h)
    hits = trace_camera(grid, tv, cam, w, h, 16)
    surface = surface_of(hits, tv, cam, w, h)
    light = np.array([2.0, 6.0, 3.0] if kind == 0 else [-0.3, -1.0, -0.2], np.float32)
    light = light if kind == 0 else light / np.linalg.norm(light)
    rays = LightRays(surface, kind, light)
    bvh = BvhAccel(SceneBvh.of_objects(len(tv), [(0, 700)]).update(tv), tv)
    vis_bvh = np.empty(len(rays.t_max), np.float32)
    vis_grid = np.empty(len(rays.t_max), np.float32)
    bvh.trace_shadows(rays, vis_bvh)
    GridAccel(grid, tv, 16).trace_shadows(rays, vis_grid)
    assert rays.n_active > 1000 and 0.05 < 1 - vis_bvh[rays.t_max > 0].mean() < 0.95
    # the BVH's own path for a camera pass: the rays made in its packets, in
    # the samples' order; every vis[i] written (the buffer starts as NaN)
    def direct(lights, rows, n_rows, skip=None):
        vis = np.full((n_rows, len(rays.t_max)), np.nan, np.float32)
        c, n = bvh.trace_lights(surface, np.array(lights, np.float32), rows, vis, skip)
        return vis, c, n
    vis_d, c, n_active = direct([[kind, *light]], [0], 1)
    vis_direct = vis_d[0]
    assert n_active == rays.n_active and c.packets >= len(rays.t_max) // 128
    assert 0 < np.count_nonzero(rays.t_max <= 0) and not np.any(vis_direct[rays.t_max <= 0])  # facing away
    graze = list(np.nonzero(vis_direct != vis_bvh)[0])
    assert len(graze) <= 3, len(graze)
    skip = rng.random(len(rays.t_max)) < 0.3
    vis_skip, _, n_left = direct([[kind, *light]], [0], 1, skip)
    assert n_left == n_active - np.count_nonzero(skip & (rays.t_max > 0))
    assert not np.any(vis_skip[0][skip]) and np.array_equal(vis_skip[0][~skip], vis_direct[~skip])
    # two lights at once (the other kind too), into rows out of order: each
    # row as that light alone, the row between untouched
    d = np.array([-0.3, -1.0, -0.2], np.float32)
    other = [1, *(d / np.linalg.norm(d))] if kind == 0 else [0, 2.0, 6.0, 3.0]
    vis_other, _, n_other = direct([other], [0], 1)
    vis_two, _, n_two = direct([other, [kind, *light]], [0, 2], 3)
    assert np.array_equal(vis_two[0], vis_other[0]) and np.array_equal(vis_two[2], vis_direct)
    assert np.all(np.isnan(vis_two[1])) and n_two == n_active + n_other
    differ = np.nonzero(vis_bvh != vis_grid)[0]
    assert len(differ) <= 3, len(differ)
    for i in list(differ) + graze:                     # each is a graze: a hit on an edge or corner
        o = np.ascontiguousarray(rays.origin[:, i][None])
        d = np.ascontiguousarray(rays.direction[:, i][None])
        ref = brute_force_closest(o, d, rays.t_min[i:i + 1], rays.t_max[i:i + 1], tv)
        mine = bvh.trace_rays(o, d, rays.t_min[i:i + 1], rays.t_max[i:i + 1])
        assert _edge(ref[1] >= 0, ref[2], ref[3])[0] or _edge(mine.prim >= 0, mine.b1, mine.b2)[0]


def test_extreme_geometry(rng):
    """All triangles in one place, degenerate and sliver triangles, huge and
    tiny ones, corners that are not finite, and an empty scene."""
    base = soup(rng, 200, spread=0.01, size=0.005)                      # everything in one spot
    sliver = np.array([[0, 0, 0, 1, 0, 0, 2, 1e-7, 0]], np.float32)
    point = np.array([[0.5, 0.5, 0.5] * 3], np.float32)                  # all three corners equal
    line = np.array([[0, 0, 0, 1, 1, 1, 2, 2, 2]], np.float32)           # collinear
    huge = np.array([[-1e6, -1, -1e6, 1e6, -1, -1e6, 0, -1, 1e6]], np.float32)
    nan = np.array([[np.nan, 0, 0, 1, np.inf, 0, 0, 1, 0]], np.float32)
    tv = np.ascontiguousarray(np.concatenate([base, sliver, point, line, huge, nan]))
    bvh = SceneBvh.of_objects(len(tv)).update(tv)
    o = np.ascontiguousarray(np.broadcast_to(np.array([0.003, 2.0, 0.004], np.float32), (500, 3)))
    d = rng.normal(size=(500, 3)).astype(np.float32)
    d[:250, 1] = -np.abs(d[:250, 1]) - 3                                  # mostly down at the cluster
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    want = brute_force_closest(o, d, np.zeros(500, np.float32), np.full(500, np.inf, np.float32), tv)
    for mode in (SHARED_ORIGIN, SINGLE):
        _agree(bvh_trace_rays(bvh, o, d, mode=mode), want, tv)
    empty = SceneBvh.of_objects(0).update(np.zeros((0, 9), np.float32))
    assert np.all(bvh_trace_rays(empty, o, d, mode=SHARED_ORIGIN)[1] == -1)


def test_camera_rays_through_the_bvh_equal_the_grids(rng):
    """Camera packets (8x8 pixels sharing the eye) hit the grid's triangles,
    with the same distances, from outside and from inside the scene."""
    tv = _scene(rng)
    grid = build_grid(tv)
    bvh = BvhAccel(SceneBvh.of_objects(len(tv), [(0, 320)]).update(tv), tv)
    w, h = 61, 45                                                        # not a multiple of 8
    for eye in ((0.0, 0.5, 6.0), (0.2, 0.3, 0.1)):
        cam = camera_basis(eye, (0.3, 0.0, -0.2), (0, 1, 0), 70.0, w, h)
        g = trace_camera(grid, tv, cam, w, h, 8)
        b, (row_off, col_off) = bvh.trace_camera(cam, w, h, (0.5, 0.5))
        idx = (row_off[:, None] + col_off[None, :]).reshape(-1)
        _agree((b.t[idx], b.prim[idx], b.b1[idx], b.b2[idx]), (g.t, g.prim, g.b1, g.b2), tv)


def test_render_with_the_bvh_records_what_it_did(tmp_path):
    """`render --accel bvh --packet 32`: a warning that the BVH traces 8x8
    packets, stats.json with the structures and the BVH's refit per frame."""
    import json

    from click.testing import CliRunner

    from cli.main import main
    from scene_files import scene_with
    path = scene_with(tmp_path, "  - {name: ball, mesh: ball.obj}\n")
    res = CliRunner().invoke(main, ["render", str(path), "-o", str(tmp_path / "out"), "--accel", "bvh",
                                    "--packet", "32", "--frames", "0:1", "-q"])
    assert res.exit_code == 0 and "BVH traces 8x8" in res.stderr, res.output
    stats = json.loads((tmp_path / "out" / "stats.json").read_text())
    run = stats["runs"][-1]
    assert (run["accel"], run["shadow_accel"], run["packet"]) == ("bvh", "bvh", 8)
    assert all("bvh_refit_ms" in f and "grid_dims" not in f for f in stats["frames"])


def test_compare_takes_all_three_structures(tmp_path):
    import json

    from click.testing import CliRunner

    from cli.main import main
    out = tmp_path / "c.json"
    res = CliRunner().invoke(main, ["compare", "grid", "vs", "kdtree", "vs", "bvh", "--scene", "demo",
                                    "--res", "48", "--frames", "1", "--json", str(out)])
    assert res.exit_code == 0, res.output
    result = json.loads(out.read_text())
    assert [r["structure"] for r in result["rows"]] == ["grid", "kdtree", "bvh"]
    assert all(d["hit_mismatch_pixels"] == 0 for d in result["diff"])


def test_the_scene_file_names_the_shadow_structure(tmp_path):
    """render.shadow_accel in the scene file reaches the frame (stats.json
    records it), and `--shadow-accel` overrides it."""
    import json

    from click.testing import CliRunner

    from cli.main import main
    from scene_files import scene_with
    path = scene_with(tmp_path, "  - {name: ball, mesh: ball.obj}\n", extra="render: {shadow_accel: grid}")
    for args, want in (([], "grid"), (["--shadow-accel", "kdtree"], "kdtree")):
        out = tmp_path / f"out_{want}"
        res = CliRunner().invoke(main, ["render", str(path), "-o", str(out), "--frames", "0:0", "-q", *args])
        assert res.exit_code == 0, res.output
        assert json.loads((out / "stats.json").read_text())["runs"][-1]["shadow_accel"] == want


def test_trees_stay_within_their_depth_bound():
    """Triangles spread over the float range (2^-125 .. 2^125) make binned
    SAH peel off a few per level (256K of them went 107 deep, past the
    traversal stack). From SAH_DEPTH down every node with more than a leaf's
    triangles is halved by count, so no tree is deeper than MAX_DEPTH; rays
    through it agree with brute force."""
    from raycore.bvh.nodes import MAX_DEPTH, MAX_LEAF, SAH_DEPTH
    n = 20000
    x = (2.0 ** np.linspace(-125, 125, n)).astype(np.float32)
    tv = np.zeros((n, 9), np.float32)
    tv[:, 0], tv[:, 3], tv[:, 6] = x, x * np.float32(1.0001), x
    tv[:, 7] = x * np.float32(1e-3)
    trees = SceneBvh.of_objects(n)
    b = trees.update(tv)
    size = lambda i: int(b.count[i]) if b.count[i] > 0 else size(b.child[i]) + size(b.child[i] + 1)  # noqa: E731
    deepest, stack = 0, [(0, 1)]
    while stack:
        i, depth = stack.pop()
        deepest = max(deepest, depth)
        if b.count[i] <= 0 and b.child[i] >= 0:
            left, right = b.child[i], b.child[i] + 1
            if depth >= SAH_DEPTH and size(i) > MAX_LEAF:
                assert abs(size(left) - size(right)) <= 1, (depth, size(left), size(right))
            stack += [(left, depth + 1), (right, depth + 1)]
    assert SAH_DEPTH < deepest <= MAX_DEPTH
    o = np.zeros((400, 3), np.float32)
    o[:, 1] = 1e-3
    d = np.zeros((400, 3), np.float32)
    d[:, 0] = 1.0                                      # along the row of triangles, grazing them all
    d[:, 1] = -np.float32(1e-3) * np.linspace(0.5, 1.5, 400, dtype=np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    want = brute_force_closest(o, d, np.zeros(400, np.float32), np.full(400, np.inf, np.float32), tv)
    for mode in (SHARED_ORIGIN, SINGLE):
        _agree(bvh_trace_rays(b, o, d, mode=mode), want, tv)


def test_refit_boxes_are_tight_and_its_cost_is_the_trees(rng):
    """After a refit every used node's box is exactly its triangles' (a leaf)
    or its children's (inner) union, and the refit's SAH cost equals
    sah_cost's: checked on a tree large enough to be refit in pieces
    (refit.refit_plan) and on small ones refit whole; the pieces cover
    every node once."""
    from raycore.bvh.refit import REFIT_MIN_NODES, refit_plan
    big = np.ascontiguousarray(soup(rng, 3000, spread=4.0, size=0.2))
    small = np.ascontiguousarray(soup(rng, 40, spread=1.0, size=0.2))
    tv0 = np.ascontiguousarray(np.concatenate([big, small, small + np.float32(3)]))
    trees = SceneBvh.of_objects(len(tv0), [(0, 3000), (3000, 3040), (3040, 3080)])
    trees.update(tv0)
    b = trees.bvh
    for g, n0 in enumerate(trees.node_lo[:3]):
        used = int(trees.used[g])
        front, ends, tops = refit_plan(b.child, b.count, int(n0), used)
        covered = np.zeros(used, int)
        for x, e in zip(front, ends):
            covered[x - n0] += 1
            if e > x + 1:
                covered[b.child[x] - n0:e - n0] += 1
        covered[tops - n0] += 1
        np.testing.assert_array_equal(covered, 1)
        assert (len(front) > 1) == (used >= REFIT_MIN_NODES)
    tv = tv0 + np.float32(0.05) * rng.normal(size=tv0.shape).astype(np.float32)
    trees.update(tv)
    assert trees.stats["bvh_rebuilt"] == 0
    _assert_tight(trees, tv)
    # corners that are not finite are left out of a leaf's box, as in the
    # build (refit checks for them once a leaf and boxes such a leaf again)
    odd = tv.copy()
    hit = rng.choice(3080, 60, replace=False)
    odd[hit, rng.integers(0, 9, 60)] = np.float32(np.inf)
    odd[hit[:20], 4] = np.float32(np.nan)
    odd[hit[:10], 0] = np.float32(-np.inf)
    odd[hit[30], :] = np.float32(np.nan)                    # no finite corner: an empty box
    trees.update(odd)
    assert trees.stats["bvh_rebuilt"] == 0
    _assert_tight(trees, odd)
    assert np.array_equal(b.verts[:3080], odd[b.tri[:3080]], equal_nan=True)


def _assert_tight(trees, tv):
    """Every used node's box is its finite corners' (a leaf) or its
    children's (inner) union, and each tree's cost is sah_cost's."""
    b = trees.bvh
    for g, n0 in enumerate(trees.node_lo[:3]):
        for i in range(int(n0), int(n0) + int(trees.used[g])):
            if b.count[i] > 0:
                corners = tv[b.tri[b.child[i]:b.child[i] + b.count[i]]].reshape(-1, 3)
                finite = np.isfinite(corners)
                lo = np.where(finite, corners, np.inf).min(0)
                hi = np.where(finite, corners, -np.inf).max(0)
                np.testing.assert_array_equal(b.box[i], np.r_[lo, hi].astype(np.float32))
            else:
                c = b.child[i]
                np.testing.assert_array_equal(b.box[i], np.r_[np.minimum(b.box[c, :3], b.box[c + 1, :3]),
                                                              np.maximum(b.box[c, 3:], b.box[c + 1, 3:])])
        assert trees.cost[g] == pytest.approx(sah_cost(b.box, b.child, b.count, int(n0)), rel=1e-6)


def test_the_bin_scale_keeps_every_bin_in_range():
    """bvh/build._bin_scale: an extent near the smallest float32 made the bin
    scale infinite, (c - lo) * scale NaN at c = lo, and int(NaN) a negative
    bin, a write outside the build's bin arrays (found under
    NUMBA_BOUNDSCHECK with triangles at 2^-125). The scale is finite, 0 for
    an extent that is 0, infinite or NaN (the axis is not binned), and every
    centroid of a binned axis lands in 0 .. N_BINS - 1."""
    from raycore.bvh.build import MAX_BIN_SCALE, N_BINS, _bin_scale
    f32 = np.float32
    for ext in (f32(0), f32(np.inf), f32(np.nan), f32(-1)):
        assert _bin_scale(ext) == 0
    assert _bin_scale(f32(1e-40)) == MAX_BIN_SCALE and np.isfinite(_bin_scale(f32(2.0 ** -149)))
    rng = np.random.default_rng(5)
    for ext in (f32(1e-40), f32(1e-30), f32(7.0), f32(3e38)):
        lo = f32(-ext / 2) if np.isfinite(f32(-ext / 2)) else f32(0)
        c = np.r_[lo, lo + ext, (lo + ext * rng.random(1000)).astype(np.float32)].astype(np.float32)
        c = c[(c >= lo) & (c <= lo + ext)]
        f = (c - lo) * _bin_scale(ext)
        assert np.all(np.isfinite(f)) and np.all(f >= 0)
        assert np.all(np.minimum(f.astype(np.int64), N_BINS - 1) <= N_BINS - 1)
        assert f.max() < N_BINS


def _build(tv, n_workers):
    """bvh/build.build_region over the triangles tv, as a SceneBvh builds a
    tree: nodes, leaf order and SAH cost."""
    from raycore.bvh.nodes import MAX_LEAF, empty_bvh
    from raycore.bvh.build import build_region, prim_bounds
    m = len(tv)
    bounds, centroids = np.empty((m, 6), np.float32), np.empty((m, 3), np.float32)
    prim_bounds(tv, np.arange(m, dtype=np.int32), bounds, centroids)
    b, order = empty_bvh(2 * m, m), np.empty(m, np.int32)
    used, cost = build_region(bounds, MAX_LEAF, 0, 0, b.box, b.child, b.count, order, n_workers)
    return b, used, cost, order


def test_a_tree_built_by_many_threads_is_the_one_built_by_one(rng, monkeypatch):
    """build_region splits the top of a tree on one thread and hands the
    subtrees below to worker threads, then lays the nodes out as one serial
    pass does: the tree (every node's box, child and count, bit for bit, and
    the leaf order) is the same for 1, 2 and 3 workers, on random triangles,
    triangles spread over the float range, triangles all in one point, and
    triangles with infinite and NaN corners. Every triangle is in exactly one
    leaf, every box holds its children's or triangles' boxes, and the cost
    build_region reports is sah_cost's (NaN for boxes whose area overflows)."""
    import raycore.bvh.build as bvh_build
    n = 6000
    spread = (2.0 ** np.linspace(-125, 125, n)).astype(np.float32)
    far = np.zeros((n, 9), np.float32)
    far[:, 0], far[:, 3], far[:, 6], far[:, 7] = spread, spread * np.float32(1.0001), spread, spread * 1e-3
    odd = soup(rng, n, spread=3.0, size=0.2)
    odd[rng.integers(0, n, 300), rng.integers(0, 9, 300)] = np.inf
    odd[rng.integers(0, n, 300), rng.integers(0, 9, 300)] = np.nan
    cases = {"soup": soup(rng, n, spread=5.0, size=0.3), "float range": far,
             "one point": np.tile(np.float32([1, 2, 3, 1, 2, 3.5, 1.5, 2, 3]), (n, 1)), "odd corners": odd}
    builds = []
    real = bvh_build._build_nodes
    monkeypatch.setattr(bvh_build, "_build_nodes", lambda *a: builds.append(a[11]) or real(*a))
    for name, tv in cases.items():
        builds.clear()
        one = _build(tv, 1)
        assert builds == [0], name                       # one pass, no tasks
        for workers in (2, 3):
            builds.clear()
            many = _build(tv, workers)
            assert builds[0] > 0 and len(builds) > workers, (name, builds)   # top phase, then tasks
            assert many[1] == one[1] and np.array_equal(many[2], one[2], equal_nan=True), name
            assert np.array_equal(many[0].node_i[:one[1]], one[0].node_i[:one[1]]), name
            assert np.array_equal(many[3], one[3]), name
        b, used, cost, order = one
        # straight from the triangles (SceneBvh's path, no box arrays): the same tree, bit for bit
        from raycore.bvh.build import build_region_of_tris
        from raycore.bvh.nodes import MAX_LEAF, empty_bvh
        direct, direct_order = empty_bvh(2 * n, n), np.empty(n, np.int32)
        sub = np.arange(n - 1, -1, -2, dtype=np.int32)             # a subset, out of order, as a group is
        for workers in (1, 2):
            got = build_region_of_tris(tv, sub, MAX_LEAF, 0, 0, direct.box, direct.child, direct.count,
                                       direct_order[:len(sub)], workers)
            want_b, want_used, want_cost, want_order = _build(tv[sub], workers)
            assert got[0] == want_used and np.array_equal(got[1], want_cost, equal_nan=True), name
            assert np.array_equal(direct.node_i[:got[0]], want_b.node_i[:want_used]), name
            assert np.array_equal(direct_order[:len(sub)], want_order), name
        assert sorted(order) == list(range(n)), name
        assert cost == pytest.approx(sah_cost(b.box, b.child, b.count, 0), rel=1e-6, nan_ok=True), name
        bounds = np.empty((n, 6), np.float32)
        from raycore.bvh.build import prim_bounds
        prim_bounds(tv, np.arange(n, dtype=np.int32), bounds, np.empty((n, 3), np.float32))
        seen = np.zeros(n, int)
        for i in range(used):
            lo, hi = b.box[i, :3], b.box[i, 3:]
            if b.count[i] > 0:
                refs = order[b.child[i]:b.child[i] + b.count[i]]
                seen[refs] += 1
                inside = [bounds[refs, :3], bounds[refs, 3:]]
            else:
                kids = b.child[i] + np.arange(2)
                inside = [b.box[kids, :3], b.box[kids, 3:]]
            boxed = inside[0] <= inside[1]                 # empty boxes (no finite corner) hold nothing
            assert np.all((inside[0] >= lo) | ~boxed) and np.all((inside[1] <= hi) | ~boxed), (name, i)
        assert np.all(seen == 1), name


def test_the_row_vector_min_and_swap_are_numpys(rng):
    """row8's intrinsics (the build's 8-lane box arithmetic) against numpy,
    with infinities (empty boxes) and signed zeros among the lanes."""
    from numba import njit
    from raycore.jit.row8 import min_rows, swap_rows

    @njit
    def run(dst, src, pairs):
        for p in range(pairs.shape[0]):
            min_rows(dst, pairs[p, 0], src, pairs[p, 1])
        swap_rows(dst, 0, dst.shape[0] - 1)

    dst = rng.normal(size=(6, 8)).astype(np.float32)
    src = rng.normal(size=(5, 8)).astype(np.float32)
    dst[1, 2], src[3, 4], src[0, 0] = np.inf, -np.inf, -0.0
    pairs = rng.integers(0, 5, size=(40, 2))
    expect = dst.copy()
    for i, k in pairs:
        expect[i] = np.where(expect[i] < src[k], expect[i], src[k])
    expect[[0, -1]] = expect[[-1, 0]]
    run(dst, src, pairs)
    assert np.array_equal(dst.view(np.uint32), expect.view(np.uint32))



def test_the_centroid_row_is_the_centroid_prim_bounds_gives(rng):
    """row8.min_centroid_rows and build._centroid (the build's centroids,
    made from a primitive's box row where they are needed) against
    prim_bounds's centroids, bit for bit: random boxes, boxes with no finite
    corner on an axis (centroid 0, -0 in the negated lanes), one-point boxes,
    signed zeros and coordinates near the float32 range's ends."""
    from numba import njit
    from raycore.bvh.build import _centroid, prim_bounds
    from raycore.jit.row8 import min_centroid_rows
    n = 400
    tv = (rng.normal(size=(n, 9)) * rng.choice([1e-30, 1.0, 1e30], size=(n, 1))).astype(np.float32)
    tv[rng.integers(0, n, 150), rng.integers(0, 9, 150)] = np.inf
    tv[rng.integers(0, n, 150), rng.integers(0, 9, 150)] = np.nan
    tv[:20] = np.nan
    tv[20:40] = np.tile(tv[20:40, :3], 3)                        # one point
    tv[40:50] = -0.0
    tv[50:60] = np.float32([3e38, -3e38, 1, -3e38, 3e38, 1, 0, 0, 1])
    bounds, centroids = np.empty((n, 6), np.float32), np.empty((n, 3), np.float32)
    prim_bounds(tv, np.arange(n, dtype=np.int32), bounds, centroids)
    rows = np.zeros((n, 8), np.float32)
    rows[:, :3], rows[:, 4:7] = bounds[:, :3], -bounds[:, 3:]
    rows.view(np.int32)[:, 3] = rng.integers(0, 2 ** 31 - 1, n)   # a primitive's number, as the build keeps it

    @njit
    def run(rows, cent, each):
        for k in range(rows.shape[0]):
            for a in range(3):
                cent[k, a] = _centroid(rows, k, a)
            each[k, :] = np.inf
            min_centroid_rows(each, k, rows, k)

    cent, each = np.empty((n, 3), np.float32), np.empty((n, 8), np.float32)
    run(rows, cent, each)
    assert np.array_equal(cent.view(np.uint32), centroids.view(np.uint32))
    want = np.zeros((n, 8), np.float32)
    want[:, :3], want[:, 4:7] = centroids, -centroids
    assert np.array_equal(each.view(np.uint32), want.view(np.uint32))

def _reachable(bvh, root=0):
    """Node ids reached from the root (the top level's), parents first."""
    out, stack = [], [root]
    while stack:
        i = stack.pop()
        out.append(i)
        if bvh.count[i] <= 0 and bvh.child[i] >= 0:
            stack += [bvh.child[i], bvh.child[i] + 1]
    return out


def test_every_built_box_is_the_exact_bound_of_its_triangles(rng):
    """The build's boxes (kept as lo and -hi rows while it splits) are exactly
    the corners' bounds: a leaf's of its triangles, an inner node's of its
    children's; every triangle is in one leaf."""
    from conftest import soup
    tv = soup(rng, 3000, spread=20.0)
    tv[:50] *= np.float32(1e-6)                             # tiny ones at the origin among them
    bvh = SceneBvh.of_objects(len(tv)).update(tv)
    seen = []
    for i in _reachable(bvh):                               # nodes past a tree's used ones are never read
        c = bvh.count[i]
        if c > 0:
            ids = bvh.tri[bvh.child[i]:bvh.child[i] + c]
            seen += list(ids)
            corners = tv[ids].reshape(-1, 3)
            assert np.array_equal(bvh.box[i, :3], corners.min(0)) and np.array_equal(bvh.box[i, 3:], corners.max(0))
        elif bvh.child[i] >= 0:
            kids = bvh.box[bvh.child[i]:bvh.child[i] + 2]
            assert np.array_equal(bvh.box[i, :3], kids[:, :3].min(0))
            assert np.array_equal(bvh.box[i, 3:], kids[:, 3:].max(0))
    assert sorted(seen) == list(range(len(tv)))


def test_many_small_trees_built_in_one_call_are_those_built_one_by_one(rng, monkeypatch):
    """A scene of many small objects (tumbling marbles) builds and rebuilds
    its small trees in one call (build_small_trees, on the threads): every
    node, reference, leaf-order corner and vertex id, refit plan and SAH
    cost is the one-by-one path's, bit for bit, for trees of 1 to
    SMALL_TREE - 1 triangles beside a large tree and a static one, with
    triangles spread over the float range, all in one point, and with
    infinite and NaN corners; the first frame's build and a frame whose
    scattered trees are rebuilt (and the refits between) both."""
    import raycore.bvh.scene as scene_bvh
    from raycore.bvh.build import SMALL_TREE
    sizes = [1, 2, 7, 8, 9, 80, 80, 80, SMALL_TREE - 1, 33, 50, 60, 70, 90, SMALL_TREE + 40, 64]
    parts = []
    for k, m in enumerate(sizes):
        part = soup(rng, m, spread=1.0, size=0.2) + np.float32(3 * k)
        if k == 2:
            part[:] = np.float32([1, 2, 3, 1, 2, 3.5, 1.5, 2, 3])            # all in one point
        if k == 8:
            part[rng.integers(0, m, 20), rng.integers(0, 9, 20)] = np.inf
            part[rng.integers(0, m, 20), rng.integers(0, 9, 20)] = np.nan
        if k == 9:
            part *= (2.0 ** np.linspace(-120, 120, m)).astype(np.float32)[:, None]
        parts.append(part)
    tv0 = np.ascontiguousarray(np.concatenate(parts))
    n = len(tv0)
    starts = np.concatenate([[0], np.cumsum(sizes)])
    ranges = [(int(starts[k]), int(starts[k + 1])) for k in range(len(sizes) - 1)]     # the last part is static
    faces = np.arange(3 * n, dtype=np.int32).reshape(n, 3)[rng.permutation(n)]        # a mesh, ids shuffled
    vertices0 = np.empty((3 * n, 3), np.float32)
    vertices0[faces.reshape(-1)] = tv0.reshape(-1, 3)
    calls = []
    batch = scene_bvh.BATCH_TREES
    real = scene_bvh.build_small_trees
    monkeypatch.setattr(scene_bvh, "build_small_trees", lambda *a: calls.append(1) or real(*a))
    batched = SceneBvh.of_objects(n, ranges, faces=faces)
    single = SceneBvh.of_objects(n, ranges, faces=faces)
    assert len(batched.groups) >= scene_bvh.BATCH_TREES

    def update_both(vertices):
        tv = np.ascontiguousarray(vertices[faces].reshape(n, 9))
        calls.clear()
        batched.update(tv, vertices)
        assert calls, "the small trees were not built in one call"
        monkeypatch.setattr(scene_bvh, "BATCH_TREES", 10 ** 9)
        calls.clear()
        single.update(tv, vertices)
        assert not calls
        monkeypatch.setattr(scene_bvh, "BATCH_TREES", batch)
        assert batched.stats["bvh_rebuilt"] == single.stats["bvh_rebuilt"]
        reached = _reachable(single.bvh)                      # nodes past a tree's used ones are never read
        assert reached == _reachable(batched.bvh)
        for a, b in ((batched.bvh.node_i[reached], single.bvh.node_i[reached]), (batched.bvh.tri, single.bvh.tri),
                     (batched.bvh.verts.view(np.int32), single.bvh.verts.view(np.int32)),
                     (batched.leaf_faces, single.leaf_faces), (batched.used, single.used),
                     (batched.cost.view(np.int32), single.cost.view(np.int32)),
                     (batched.built_cost.view(np.int32), single.built_cost.view(np.int32))):
            np.testing.assert_array_equal(a, b)
        live = single.front >= 0
        np.testing.assert_array_equal(batched.front, single.front)
        np.testing.assert_array_equal(batched.front_end[live], single.front_end[live])
        np.testing.assert_array_equal(batched.tops, single.tops)
        return batched.stats["bvh_rebuilt"]

    assert update_both(vertices0) == len(batched.groups)
    # every moving triangle elsewhere within its object: each tree is rebuilt
    vertices = vertices0.copy()
    for s, e in ranges:
        ids = faces[s:e].reshape(-1)
        vertices[ids] = vertices0[ids][rng.permutation(len(ids))]
    assert update_both(vertices) >= scene_bvh.BATCH_TREES
