"""Watertight ray/triangle test."""
import numpy as np
import pytest

from conftest import icosphere_mesh, tri_verts_of
from oracles import RAY_CHUNK, brute_force_closest, brute_force_closest_one_by_one
from raycore.grid.build import build_grid
from raycore.grid.trace import trace_rays
from raycore.geometry.triangle import intersect_ray


def rays_at(points, origin):
    o = np.tile(np.asarray(origin, np.float32), (len(points), 1))
    return o, np.ascontiguousarray(points - o, np.float32)


def test_rays_through_shared_edges_and_vertices_never_miss():
    v, f = icosphere_mesh(level=3)
    tv = tri_verts_of(v, f)
    edges = np.concatenate([(v[f[:, a]] + v[f[:, b]]) / 2 for a, b in ((0, 1), (1, 2), (2, 0))])
    targets = np.concatenate([v, edges]).astype(np.float32)
    for origin in ([0.0, 0.0, 0.0], [0.013, -0.021, 0.007], [5.0, 3.0, 4.0]):
        o, d = rays_at(targets, origin)
        if origin[0] == 5.0:
            # from outside: rays that cross the surface (not grazing the silhouette,
            # where a ray may touch the closed mesh only at a rounded point)
            cos = -np.einsum("ij,ij->i", targets, d) / (np.linalg.norm(targets, axis=1) * np.linalg.norm(d, axis=1))
            o, d = o[cos > 0.2], d[cos > 0.2]
            assert len(o) > 500
        n = len(o)
        t, prim, _, _ = brute_force_closest(o, d, np.zeros(n, np.float32), np.full(n, np.inf, np.float32), tv)
        assert np.all(prim >= 0), f"{np.sum(prim < 0)} rays slipped through from {origin}"
        grid = build_grid(tv)
        hits = trace_rays(grid, tv, o, d, packet=8)
        assert np.all(hits.prim >= 0)


def test_the_fast_oracle_equals_the_plain_one(rng):
    """brute_force_closest (triangles against chunks of rays, vectorized)
    gives exactly what the plainest loop through intersect_ray gives, on
    random rays and on the adversarial ones: through shared vertices and
    edges, along the axes (zero direction components), at duplicated
    triangles (the first of equal hits wins), cut short by t_min and t_max,
    at degenerate triangles and at huge and tiny coordinates; a ray count
    that is not a multiple of the chunk."""
    from conftest import soup
    v, f = icosphere_mesh(level=2)
    sphere = tri_verts_of(v, f)
    flat = np.array([[0, 0, 0, 1, 1, 1, 2, 2, 2], [0, 0, 0, 0, 0, 0, 0, 0, 0],
                     [0, 0, 0, 1, 0, 0, 0.5, 1e-7, 0]], np.float32)
    tv = np.ascontiguousarray(np.concatenate([soup(rng, 300, spread=3.0), sphere, sphere[:50], flat,
                                              soup(rng, 20, spread=3e15, size=1e15), soup(rng, 20, spread=3e-15,
                                                                                       size=1e-15)]))
    edges = (v[f[:, 0]] + v[f[:, 1]]) / 2
    targets = np.concatenate([v, edges, rng.normal(size=(500, 3))]).astype(np.float32)
    origins = np.concatenate([np.zeros((len(targets), 3)), rng.normal(size=(len(targets), 3)) * 4]).astype(np.float32)
    dirs = np.concatenate([targets, targets]) - origins
    axis = rng.integers(0, 3, 300)                       # along an axis, or in an axis plane
    dirs[:300] = 0
    dirs[np.arange(300), axis] = rng.choice([-1.0, 1.0], 300)
    dirs[300:600, axis[:300]] = 0
    # at the huge triangles from far away, at the tiny ones from the origin
    centres = tv[-40:].reshape(-1, 3, 3).mean(axis=1)
    far = np.where(np.arange(40)[:, None] < 20, [0, 0, 1e16], 0).astype(np.float32)
    origins = np.concatenate([origins, far]).astype(np.float32)
    dirs = np.ascontiguousarray(np.concatenate([dirs, centres - far]), np.float32)
    n = len(origins)
    assert n % RAY_CHUNK != 0
    t_min = np.where(rng.random(n) < 0.2, rng.random(n) * 2, 0).astype(np.float32)
    t_max = np.where(rng.random(n) < 0.2, rng.random(n) * 3, np.inf).astype(np.float32)
    want = brute_force_closest_one_by_one(origins, dirs, t_min, t_max, tv)
    got = brute_force_closest(origins, dirs, t_min, t_max, tv)
    for a, b in zip(got, want):
        np.testing.assert_array_equal(a, b)
    assert 0.2 < np.mean(want[1] >= 0) < 0.95 and np.any((want[1] >= len(tv) - 40))
    assert np.any((want[1] >= 300) & (want[1] < 300 + 50))           # a duplicated triangle: the first of the two


def test_degenerate_and_sliver_triangles_give_no_nan():
    tv = np.array([[0, 0, 0, 1, 1, 1, 2, 2, 2],           # collinear: zero area
                   [0, 0, 0, 0, 0, 0, 0, 0, 0],           # a point
                   [0, 0, 0, 1, 0, 0, 0.5, 1e-7, 0]],     # sliver
                  np.float32)
    # from (0.5, 0, 1): zero-area triangles are never hit; the sliver is hit
    # straight down on its long edge and, along (0.5, 0, -1), on its vertex
    # (1, 0, 0), both inclusive; upward it is missed
    expected = {(2, 0): (1.0, 0.5), (2, 2): (1.0, 1.0)}
    for tri in range(3):
        for k, d in enumerate(([0, 0, -1], [1, 1, 1], [0.5, 0.0, -1])):
            hit, t, b1, b2 = intersect_ray(np.float32(0.5), np.float32(0.0), np.float32(1.0),
                                           *np.asarray(d, np.float32), tv, tri,
                                           np.float32(0), np.float32(np.inf))
            assert hit == ((tri, k) in expected)
            assert not hit or (t, b1) == pytest.approx(expected[tri, k]) and np.isfinite(b2)
    hit, *_ = intersect_ray(np.float32(0.5), np.float32(1e-8), np.float32(1.0),
                            np.float32(0), np.float32(0), np.float32(-1), tv, 0,
                            np.float32(0), np.float32(np.inf))
    assert not hit                                           # zero-area triangle is never hit


def test_hit_distance_and_barycentrics():
    tv = np.array([[0, 0, -2, 1, 0, -2, 0, 1, -2]], np.float32)
    hit, t, b1, b2 = intersect_ray(np.float32(0.25), np.float32(0.5), np.float32(0),
                                   np.float32(0), np.float32(0), np.float32(-1), tv, 0,
                                   np.float32(0), np.float32(np.inf))
    assert hit and abs(t - 2.0) < 1e-6 and abs(b1 - 0.25) < 1e-6 and abs(b2 - 0.5) < 1e-6
