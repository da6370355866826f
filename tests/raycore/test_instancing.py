"""Instanced worlds (raycore/instancing): the same seeded rays through the
two-level structure and, by brute force, through the flattened world (every
copy's triangles written out under its transform); frames of the two against
each other; the top level's placement of hidden and degenerate copies."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import icosphere_mesh, soup
from oracles import brute_force_closest, kernel_camera_rays
from raycore.geometry.camera import camera_basis
from raycore.geometry.mesh import vertex_face_csr
from raycore.instancing.world import InstanceFrame, InstancedStructures
from test_accelerators import agree, near_edge


def transforms(rng, k, spread=2.5):
    """k random world-from-object 3x4s: rotations, non-uniform scales (one
    copy mirrored), translations; copy 1 hidden (a zero 3x3)."""
    m = np.zeros((k, 3, 4))
    scale = rng.uniform(0.3, 0.9, (k, 3))
    scale[0, 0] *= -1                                      # mirrored: the winding flips
    m[:, :, :3] = Rotation.random(k, random_state=int(rng.integers(1 << 30))).as_matrix() * scale[:, None, :]
    m[:, :, 3] = rng.uniform(-spread, spread, (k, 3))
    m[1, :, :3] = 0.0
    return m


def world(rng, k=12):
    """(vertices, faces, InstanceFrame, flattened tri_verts, flattened copy of each ray's triangle)
    of a world (a soup and a floor) with k copies of a sphere and k of a bent strip."""
    sv, sf = icosphere_mesh(2, 1.0)
    strip_v = np.array([[x, 0.3 * np.sin(x), z] for x in np.linspace(-1, 1, 9) for z in (-0.4, 0.4)], np.float32)
    strip_f = np.array([[2 * i, 2 * i + 2, 2 * i + 1] for i in range(8)] + [[2 * i + 1, 2 * i + 2, 2 * i + 3]
                                                                            for i in range(8)], np.int32)
    loose = soup(rng, 200, spread=4.0, size=0.25).reshape(-1, 3)
    floor = np.array([[-4, -3, -4], [4, -3, -4], [4, -3, 4], [-4, -3, 4]], np.float32)
    vertices = np.concatenate([loose, floor, sv, strip_v]).astype(np.float32)
    n_loose = len(loose)
    faces = [np.arange(n_loose, dtype=np.int32).reshape(-1, 3), n_loose + np.array([[0, 2, 1], [0, 3, 2]]),
             n_loose + 4 + sf, n_loose + 4 + len(sv) + strip_f]
    sizes = np.cumsum([0] + [len(f) for f in faces])
    faces = np.ascontiguousarray(np.concatenate(faces), np.int32)
    ranges = np.array([[sizes[2], sizes[3]], [sizes[3], sizes[4]]], np.int64)
    mats = np.concatenate([transforms(rng, k), transforms(rng, k)])
    proto = np.r_[np.zeros(k, np.int32), np.ones(k, np.int32)]
    frame = InstanceFrame(ranges, np.array([False, True]), proto, mats, np.full(2 * k, -1, np.int32),
                          np.zeros(2 * k, np.int64), np.zeros(len(faces), np.int64))
    return vertices, faces, frame


def flattened(vertices, faces, frame):
    """Every world triangle, then every copy's, as tri_verts (n, 9)."""
    tv = vertices[faces].reshape(-1, 9)
    in_world = np.ones(len(faces), bool)
    for s, e in frame.ranges:
        in_world[s:e] = False
    out = [tv[in_world]]
    for m, p in zip(frame.matrices, frame.proto):
        s, e = frame.ranges[p]
        corners = tv[s:e].reshape(-1, 3).astype(np.float64)
        out.append((corners @ m[:, :3].T + m[:, 3]).astype(np.float32).reshape(-1, 9))
    return np.ascontiguousarray(np.concatenate(out), np.float32)


def structure(vertices, faces, frame):
    from raycore.instancing.accel import InstancedAccel
    s = InstancedStructures(faces, len(vertices), *vertex_face_csr(faces, len(vertices)), frame.ranges,
                            frame.moving)
    tri_verts, bvh, top, place = s.update(vertices, frame)
    return s, InstancedAccel(top, bvh, place)


def seeded_rays(rng, flat, n=600):
    o = rng.uniform(-3.0, 3.0, (n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    d[:100] = 0                                             # axis-parallel, both signs
    d[np.arange(100), rng.integers(0, 3, 100)] = rng.choice([-1.0, 1.0], 100)
    d[100:200, rng.integers(0, 3)] = 0                      # one zero component
    corners = flat[rng.integers(0, len(flat), 200)].reshape(-1, 3, 3)
    d[200:300] = corners[:100, 0] - o[200:300]              # through vertices of the world and of copies
    d[300:400] = 0.5 * (corners[100:, 0] + corners[100:, 1]) - o[300:400]     # through edge midpoints
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o, np.ascontiguousarray(d, np.float32)


def test_instanced_rays_match_brute_force_over_the_flattened_world(rng):
    """Closest hits, any hits and any hits cut short, of random,
    axis-parallel and vertex- and edge-aimed rays, starting inside the
    world, through the two-level structure against brute force over every
    copy's triangles (mirrored and non-uniformly scaled copies, a hidden
    one, a deforming prototype refit after it moved)."""
    vertices, faces, frame = world(rng)
    s, _ = structure(vertices, faces, frame)
    # the strip deforms: its tree is refit to the next frame's vertices
    strip = slice(vertices.shape[0] - 18, vertices.shape[0])
    vertices = vertices.copy()
    vertices[strip, 1] *= -1.5
    from raycore.instancing.accel import InstancedAccel
    _, bvh, top, place = s.update(vertices, frame)
    accel = InstancedAccel(top, bvh, place)
    flat = flattened(vertices, faces, frame)
    o, d = seeded_rays(rng, flat)
    n = len(o)
    want = brute_force_closest(o, d, np.zeros(n, np.float32), np.full(n, np.inf, np.float32), flat)
    got = accel.trace_rays(o, d)
    agree(got[:4], want)
    assert np.mean(want[1] >= 0) > 0.5 and got.counters.tests > 0
    # the instance and triangle of each hit name the flattened triangle that brute force hit
    hit = (got.prim >= 0) & (want[1] >= 0) & ~near_edge(want[2], want[3])
    assert np.allclose(got.b1[hit], want[2][hit], atol=1e-3)
    anyh = accel.trace_rays(o, d, any_hit=True)
    grazing = near_edge(want[2], want[3])
    assert np.all((anyh.prim >= 0)[want[1] >= 0] | grazing[want[1] >= 0])
    t_max = np.where(want[1] >= 0, want[0] * 0.9, np.inf).astype(np.float32)
    short_want = brute_force_closest(o, d, np.zeros(n, np.float32), t_max, flat)
    short = accel.trace_rays(o, d, t_max=t_max, any_hit=True)
    differ = (short.prim >= 0) != (short_want[1] >= 0)
    assert not np.any(differ & ~near_edge(short_want[2], short_want[3]) & ~near_edge(short.b1, short.b2))


@pytest.mark.parametrize("eye", [(0.2, 0.3, 0.1), (0.0, 1.0, 7.0)])     # among the copies, and outside
def test_instanced_camera_packets_match_brute_force(rng, eye):
    vertices, faces, frame = world(rng)
    _, accel = structure(vertices, faces, frame)
    flat = flattened(vertices, faces, frame)
    w, h = 48, 40
    cam = camera_basis(eye, (0.3, 0.0, -0.2), (0, 1, 0), 70.0, w, h)
    o, d = kernel_camera_rays(cam, w, h, np.float32(0.5), np.float32(0.5))
    want = brute_force_closest(o, d, np.zeros(w * h, np.float32), np.full(w * h, np.inf, np.float32), flat)
    hits, (row_off, col_off) = accel.trace_camera(cam, w, h, (0.5, 0.5))
    idx = (row_off[:, None] + col_off[None, :]).reshape(-1)
    agree((hits.t[idx], hits.prim[idx], hits.b1[idx], hits.b2[idx]), want)
    assert np.all((hits.inst[idx] >= 0) == (hits.prim[idx] >= 0))


def test_hidden_and_empty_copies_leave_the_top_level(rng):
    """A hidden copy (zero 3x3) and one scaled beyond float32's inverse are
    left out; the world's trees come first under the identity."""
    vertices, faces, frame = world(rng, k=4)
    frame.matrices[2, :, :3] = np.eye(3) * 1e-39
    s, accel = structure(vertices, faces, frame)
    place = accel.place
    assert place.identity.sum() == len(s.world_trees)
    assert len(place.tree) == len(s.world_trees) + 2 * 4 - 3     # copy 1 of each prototype hidden, copy 2 tiny
    eye = np.eye(3, 4, dtype=np.float32).reshape(12)
    assert np.array_equal(place.inverse[0], eye)
    k = len(s.world_trees)
    shown = [j for j in range(8) if j not in (1, 2, 5)]
    lin = frame.matrices[shown]
    back = place.forward[k:].reshape(-1, 3, 4)
    assert np.allclose(back, lin.astype(np.float32))
    prod = np.einsum("nij,njk->nik", place.inverse[k:].reshape(-1, 3, 4)[:, :, :3].astype(np.float64), lin[:, :, :3])
    assert np.allclose(prod, np.eye(3), atol=1e-5)
