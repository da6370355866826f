"""Mesh primitives for the built-in scenes: float64 vertices, int faces
(counter-clockwise seen from outside), optional UVs. Deterministic."""
import numpy as np


def icosphere(level=3, radius=1.0):
    """Subdivided icosahedron: 20 * 4^level triangles."""
    t = (1 + 5 ** 0.5) / 2
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
             (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    verts = [np.array(v, float) / np.linalg.norm(v) for v in verts]
    for _ in range(level):
        cache, new_faces = {}, []

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = verts[a] + verts[b]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new_faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new_faces
    return np.array(verts) * radius, np.array(faces)


def _ring_faces(n_rings, n_around, offset=0):
    """Quads between consecutive rings of n_around vertices, as triangles."""
    i, j = np.meshgrid(np.arange(n_rings - 1), np.arange(n_around), indexing="ij")
    p00 = i * n_around + j
    p01 = i * n_around + (j + 1) % n_around
    p10 = (i + 1) * n_around + j
    p11 = (i + 1) * n_around + (j + 1) % n_around
    return offset + np.concatenate([np.stack([p00, p11, p10], -1).reshape(-1, 3),
                                    np.stack([p00, p01, p11], -1).reshape(-1, 3)])


def _frame(axis):
    """Two unit vectors perpendicular to axis (and to each other)."""
    axis = axis / np.linalg.norm(axis)
    helper = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 0, 1.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)


def capsule(a, b, radius, n_around=16, n_along=8, n_cap=4, radius_b=None):
    """A tube from point a to point b with hemispherical ends. Returns
    (vertices, faces, s) with s in [0, 1] the position of each vertex along
    a -> b (for skinning weights)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    radius_b = radius if radius_b is None else radius_b
    axis = b - a
    length = np.linalg.norm(axis)
    d = axis / length
    u, w = _frame(d)
    ang = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    rings = []          # (centre distance along the axis, ring radius)
    for k in range(1, n_cap + 1):               # cap at a, from the pole outwards
        phi = np.pi / 2 * k / n_cap
        rings.append((-radius * np.cos(phi), radius * np.sin(phi)))
    for k in range(1, n_along):
        s = k / n_along
        rings.append((s * length, radius + (radius_b - radius) * s))
    for k in range(n_cap, 0, -1):               # cap at b
        phi = np.pi / 2 * k / n_cap
        rings.append((length + radius_b * np.cos(phi), radius_b * np.sin(phi)))
    verts, s_of = [a - d * radius], [0.0]
    for dist, r in rings:
        c = a + d * dist
        ring = c + r * (np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * w)
        verts.extend(ring)
        s_of.extend([min(max(dist / length, 0.0), 1.0)] * n_around)
    verts.append(b + d * radius_b)
    s_of.append(1.0)
    n_r = len(rings)
    faces = [_ring_faces(n_r, n_around, 1)]
    j = np.arange(n_around)
    faces.append(np.stack([np.zeros(n_around, int), 1 + (j + 1) % n_around, 1 + j], -1))
    last = 1 + (n_r - 1) * n_around
    tip = len(verts) - 1
    faces.append(np.stack([np.full(n_around, tip), last + j, last + (j + 1) % n_around], -1))
    return np.array(verts), np.concatenate(faces), np.array(s_of)


def ellipsoid(center, radii, n_lat=16, n_lon=24):
    """A UV sphere scaled by radii (3,)."""
    lat = np.linspace(0, np.pi, n_lat + 1)[1:-1]
    lon = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    ring = np.stack([np.sin(lat)[:, None] * np.cos(lon), np.cos(lat)[:, None] * np.ones_like(lon),
                     np.sin(lat)[:, None] * np.sin(lon)], -1).reshape(-1, 3)
    verts = np.concatenate([[[0, 1, 0]], ring, [[0, -1, 0]]]) * radii + center
    j = np.arange(n_lon)
    n_r = len(lat)
    faces = [_ring_faces(n_r, n_lon, 1)]
    faces.append(np.stack([np.zeros(n_lon, int), 1 + (j + 1) % n_lon, 1 + j], -1))
    last = 1 + (n_r - 1) * n_lon
    faces.append(np.stack([np.full(n_lon, len(verts) - 1), last + j, last + (j + 1) % n_lon], -1))
    return verts, np.concatenate(faces)


def cone(base_center, height, radius, n_around=16, n_rings=4):
    """A closed cone standing on base_center, tip height above it (+y)."""
    ang = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    rings = []
    for k in range(n_rings):
        f = k / n_rings
        rings.append(np.stack([radius * (1 - f) * np.cos(ang), np.full(n_around, height * f),
                               radius * (1 - f) * np.sin(ang)], -1))
    verts = np.concatenate([np.concatenate(rings), [[0, height, 0], [0, 0, 0]]]) + base_center
    j = np.arange(n_around)
    last = (n_rings - 1) * n_around
    faces = [_ring_faces(n_rings, n_around),
             np.stack([np.full(n_around, len(verts) - 2), last + (j + 1) % n_around, last + j], -1),
             np.stack([np.full(n_around, len(verts) - 1), j, (j + 1) % n_around], -1)]
    return verts, np.concatenate(faces)


def box(lo, hi):
    """An axis-aligned closed box, 12 triangles; each face has its own four
    vertices, so that vertex normals keep the edges sharp."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
    corners = lo + c * (hi - lo)
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    verts = np.concatenate([corners[list(q)] for q in quads])
    faces = [f for k in range(6) for f in ((4 * k, 4 * k + 1, 4 * k + 2), (4 * k, 4 * k + 2, 4 * k + 3))]
    return verts, np.array(faces)


def heightfield(size, n, height_fn, uv_repeat=1.0):
    """An n x n quad grid over [-size/2, size/2]^2 at y = height_fn(x, z), with UVs."""
    xs = np.linspace(-size / 2, size / 2, n + 1)
    X, Z = np.meshgrid(xs, xs, indexing="ij")
    verts = np.stack([X, height_fn(X, Z), Z], -1).reshape(-1, 3)
    uvs = np.stack([(X / size + 0.5) * uv_repeat, (Z / size + 0.5) * uv_repeat], -1).reshape(-1, 2)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a, b = i * (n + 1) + j, (i + 1) * (n + 1) + j
    faces = np.concatenate([np.stack([a, a + 1, b + 1], -1).reshape(-1, 3),
                            np.stack([a, b + 1, b], -1).reshape(-1, 3)])
    return verts, faces, uvs


def merge(parts):
    """Concatenate [(verts, faces), ...] into one mesh."""
    verts, faces, offset = [], [], 0
    for v, f in parts:
        verts.append(v)
        faces.append(np.asarray(f) + offset)
        offset += len(v)
    return np.concatenate(verts), np.concatenate(faces)
