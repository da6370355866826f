"""Watertight ray/triangle test."""
import numpy as np
import pytest

from conftest import icosphere_mesh, tri_verts_of
from oracles import brute_force_closest
from raycore.grid_build import build_grid
from raycore.trace import trace_rays
from raycore.triangle import intersect_ray


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
