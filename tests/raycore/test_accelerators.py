"""One harness for every acceleration structure through its common surface
(raycore/accelerators.py): the same seeded rays — random, axis-parallel,
with zero direction components, aimed at vertices and edge midpoints, from
inside the structure — through the grid with and without culling, the
kd-tree and the BVH, against brute force over all triangles: closest hit, any hit, and
any hit cut short before the closest hit."""
import numpy as np
import pytest

from conftest import icosphere_mesh, soup, tri_verts_of
from oracles import brute_force_closest, kernel_camera_rays
from raycore.accelerators import BvhAccel, GridAccel, KdAccel
from raycore.geometry.camera import camera_basis
from raycore.grid.build import build_grid
from raycore.kdtree.build import build_kdtree
from raycore.bvh.scene import SceneBvh


def scene(rng):
    v, f = icosphere_mesh(2, 1.0)
    quad = np.array([[-3, -1.5, -3, 3, -1.5, -3, 3, -1.5, 3], [-3, -1.5, -3, 3, -1.5, 3, -3, -1.5, 3]], np.float32)
    return np.ascontiguousarray(np.concatenate([tri_verts_of(v, f), soup(rng, 300, spread=5.0, size=0.25), quad]))


N_SPHERE = 320                                   # the icosphere's triangles come first


def rays(rng, tv):
    """(origins, dirs) of the adversarial mix, all starting inside the scene's
    box; rays 200..400 aim at vertices and edge midpoints of the closed
    sphere."""
    n = 600
    o = rng.uniform(-2.5, 2.5, (n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    d[:100, :] = 0                                         # axis-parallel, both signs
    d[np.arange(100), rng.integers(0, 3, 100)] = rng.choice([-1.0, 1.0], 100)
    d[100:200, rng.integers(0, 3)] = 0                     # one zero component
    corners = tv[rng.integers(0, N_SPHERE, 100)].reshape(-1, 3, 3)
    d[200:300] = corners[:, 0] - o[200:300]                # through vertices
    d[300:400] = 0.5 * (corners[:, 0] + corners[:, 1]) - o[300:400]    # through edge midpoints
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o, np.ascontiguousarray(d, np.float32)


def accelerators(tv):
    grid = build_grid(tv)
    # the BVH as a renderer makes it: the sphere a moving object, the rest static
    trees = SceneBvh.of_objects(len(tv), [(0, N_SPHERE)])
    return {"grid": GridAccel(grid, tv, 8), "grid-nocull": GridAccel(grid, tv, 8, cull=False),
            "kdtree": KdAccel(build_kdtree(tv), tv), "bvh": BvhAccel(trees.update(tv), tv)}


def near_edge(b1, b2, eps=1e-4):
    """Barycentrics within eps of an edge (a miss's are undefined: False)."""
    with np.errstate(invalid="ignore"):
        return np.minimum(np.minimum(b1, b2), 1 - b1 - b2) < eps


def agree(got, want):
    """Same hit or miss, and the same distance, except where a ray grazes an
    edge or corner of an open triangle (either answer is right to float32
    precision; the barycentrics of the hit say so). Where the triangle
    differs (a shared edge or vertex may go to either), the same distance."""
    got_t, got_prim, got_b1, got_b2 = got
    want_t, want_prim, want_b1, want_b2 = want
    differ = (got_prim >= 0) != (want_prim >= 0)
    grazing = np.where(want_prim >= 0, near_edge(want_b1, want_b2), near_edge(got_b1, got_b2))
    assert not np.any(differ & ~grazing), np.nonzero(differ & ~grazing)[0]
    both = (got_prim >= 0) & (want_prim >= 0)
    close = np.isclose(got_t[both], want_t[both], rtol=2e-5, atol=1e-6)
    assert np.all(close | grazing[both]), np.nonzero(both)[0][~(close | grazing[both])]


@pytest.mark.parametrize("name", ["grid", "grid-nocull", "kdtree", "bvh"])
def test_closest_any_and_short_any_hit_match_brute_force(rng, name):
    tv = scene(rng)
    o, d = rays(rng, tv)
    n = len(o)
    want = brute_force_closest(o, d, np.zeros(n, np.float32), np.full(n, np.inf, np.float32), tv)
    # rays aimed at the closed sphere's vertices and edges, not at a grazing
    # angle: a watertight structure hits every one (the brute-force oracle's
    # test is not watertight at vertices, so it is not the judge here)
    target = o + d * np.einsum("ij,ij->i", -o, d)[:, None]          # nearest point to the centre
    aimed = np.zeros(n, bool)
    aimed[200:400] = np.linalg.norm(target[200:400], axis=1) < 0.9
    accel = accelerators(tv)[name]
    h = accel.trace_rays(o, d)
    assert np.all(h.prim[aimed] >= 0), np.nonzero(aimed & (h.prim < 0))[0]
    agree(h[:4], want)
    assert h.counters.tests > 0
    anyh = accel.trace_rays(o, d, any_hit=True)
    hit_want = want[1] >= 0
    assert np.all((anyh.prim >= 0)[hit_want] | near_edge(want[2], want[3])[hit_want])
    assert np.all(anyh.prim[aimed] >= 0)
    miss = want[1] < 0
    assert not np.any((anyh.prim >= 0) & miss & ~near_edge(anyh.b1, anyh.b2))
    # cut short at 90% of the closest hit: brute force and the structure agree
    t_max = np.where(want[1] >= 0, want[0] * 0.9, np.inf).astype(np.float32)
    short_want = brute_force_closest(o, d, np.zeros(n, np.float32), t_max, tv)
    short = accel.trace_rays(o, d, t_max=t_max, any_hit=True)
    differ = (short.prim >= 0) != (short_want[1] >= 0)
    grazing = np.where(short_want[1] >= 0, near_edge(short_want[2], short_want[3]), near_edge(short.b1, short.b2))
    assert not np.any(differ & ~grazing)


@pytest.mark.parametrize("eye", [(0.2, 0.3, 0.1), (0.0, 0.5, 6.0)])      # inside the sphere, and outside
def test_camera_rays_from_inside_and_outside_match_brute_force(rng, eye):
    tv = scene(rng)
    w, h = 48, 40
    cam = camera_basis(eye, (0.3, 0.0, -0.2), (0, 1, 0), 70.0, w, h)
    o, d = kernel_camera_rays(cam, w, h, np.float32(0.5), np.float32(0.5))
    n = w * h
    want = brute_force_closest(o, d, np.zeros(n, np.float32), np.full(n, np.inf, np.float32), tv)
    for name, accel in accelerators(tv).items():
        hits, (row_off, col_off) = accel.trace_camera(cam, w, h, (0.5, 0.5))
        idx = (row_off[:, None] + col_off[None, :]).reshape(-1)
        agree((hits.t[idx], hits.prim[idx], hits.b1[idx], hits.b2[idx]), want)
        assert hits.counters.packets > 0, name


@pytest.mark.parametrize("name", ["grid", "bvh"])
def test_every_structure_auto_picks_matches_brute_force_on_a_million_triangles(rng, name):
    """The structures `render.accel: auto` chooses between (the grid and the
    BVH), on the 1M-triangle rippling torus of `bench --scale`: camera rays
    at random pixels, rays from inside it in random and axis-parallel
    directions and through its vertices, against brute force over all
    triangles."""
    from anim.measure.scale import torus
    v, f = torus(1_000_000, 0.3)
    tv = tri_verts_of(np.asarray(v, np.float32), np.asarray(f, np.int32))
    assert len(tv) >= 990_000
    n = 240
    o = np.empty((n, 3), np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    o[:80] = (0.0, 2.6, 2.9)                                                # the camera, at random pixels
    d[:80] = rng.uniform(-0.4, 0.4, (80, 3)) + np.float32([0, -2.2, -2.9])
    o[80:] = rng.uniform(-1.2, 1.2, (n - 80, 3)) * np.float32([1, 0.5, 1]) + np.float32([0, 0.4, 0])
    d[80:140] = 0
    d[np.arange(80, 140), rng.integers(0, 3, 60)] = rng.choice([-1.0, 1.0], 60)   # axis-parallel
    d[140:200] = tv[rng.integers(0, len(tv), 60), :3] - o[140:200]              # through vertices
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = np.ascontiguousarray(d, np.float32)
    want = brute_force_closest(o, d, np.zeros(n, np.float32), np.full(n, np.inf, np.float32), tv)
    assert (want[1] >= 0).mean() > 0.5
    accel = (GridAccel(build_grid(tv), tv, 8) if name == "grid"
             else BvhAccel(SceneBvh.of_objects(len(tv), [(0, len(tv))]).update(tv), tv))
    agree(accel.trace_rays(o, d)[:4], want)
    anyh = accel.trace_rays(o, d, any_hit=True)
    hit_want = want[1] >= 0
    assert np.all((anyh.prim >= 0)[hit_want] | near_edge(want[2], want[3])[hit_want])
