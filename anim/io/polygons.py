"""Polygons as triangles: a fan where the polygon is convex (quads and convex
n-gons, as most files hold), ear clipping (mapbox-earcut) where it is not.

A fan of a concave polygon covers its notch and makes overlapping triangles
(an L-shaped hexagon fanned from a corner fills the L's inside corner). A
polygon is taken as convex when, in the plane of its Newell normal, every
turn has one sign; it is then fanned from its first corner exactly as
before, so files of convex polygons give the same triangles. The test runs
on all polygons of one corner count at once (numpy), so a mesh of a million
quads is checked in well under a second.
"""
import numpy as np


def split_at_seams(faces, *corner_values):
    """Vertices split only where a point's corners differ: (point_of (k,) the
    point of each new vertex, its values (k, c) from corner_values, faces
    (n_t, 3) over the new vertices). faces (n_t, 3) are point ids; each of
    corner_values has a row of values per corner, in faces' order (UVs,
    normal ids): a vertex per distinct (point, values)."""
    n = faces.size
    keyed = np.concatenate([faces.reshape(n, 1).astype(np.float64),
                            *(np.asarray(v, np.float64).reshape(n, -1) for v in corner_values)], axis=1)
    unique, inverse = np.unique(keyed, axis=0, return_inverse=True)
    return unique[:, 0].astype(np.int64), unique[:, 1:], inverse.reshape(-1, 3)


def fan(counts, starts):
    """(corner (n_t, 3) indices into the polygons' corner list, polygon of
    each triangle): each polygon fanned from its first corner."""
    n_tri = np.maximum(counts - 2, 0)
    poly = np.repeat(np.arange(len(counts)), n_tri)
    k = np.arange(n_tri.sum()) - np.repeat(np.cumsum(n_tri) - n_tri, n_tri)      # triangle within polygon
    corner = np.stack([starts[poly], starts[poly] + k + 1, starts[poly] + k + 2], axis=1)
    return corner, poly


def plane_coordinates(p):
    """(k, m, 2) coordinates of k polygons' points p (k, m, 3) in the plane of
    each one's Newell normal, and the normals' lengths (k,) (0: no area)."""
    q = np.roll(p, -1, axis=1)
    normal = np.stack([np.sum((p[..., 1] - q[..., 1]) * (p[..., 2] + q[..., 2]), axis=1),
                       np.sum((p[..., 2] - q[..., 2]) * (p[..., 0] + q[..., 0]), axis=1),
                       np.sum((p[..., 0] - q[..., 0]) * (p[..., 1] + q[..., 1]), axis=1)], axis=1)
    length = np.linalg.norm(normal, axis=1)
    n = normal / np.where(length > 0, length, 1.0)[:, None]
    helper = np.where((np.abs(n[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    u = np.cross(n, helper)
    u /= np.where(np.linalg.norm(u, axis=1) > 0, np.linalg.norm(u, axis=1), 1.0)[:, None]
    v = np.cross(n, u)
    return np.stack([np.einsum("kmi,ki->km", p, u), np.einsum("kmi,ki->km", p, v)], axis=2), length


def convex(xy):
    """(k,) whether each polygon xy (k, m, 2) turns one way at every corner
    (collinear corners allowed)."""
    a, b, c = xy, np.roll(xy, -1, axis=1), np.roll(xy, -2, axis=1)
    turn = (b[..., 0] - a[..., 0]) * (c[..., 1] - b[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - b[..., 0])
    return np.all(turn >= 0, axis=1) | np.all(turn <= 0, axis=1)


def triangulate(counts, indices, points):
    """(faces (n_t, 3) point indices, corner (n_t, 3) indices into
    `indices`, polygon of each triangle) of polygons given by their corner
    counts and point indices; points (n, 3) decide convexity. Each polygon's
    n - 2 triangles stay where its fan's were."""
    counts = np.asarray(counts, np.int64)
    indices = np.asarray(indices, np.int64)
    points = np.asarray(points, np.float64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    corner, poly = fan(counts, starts)
    first_tri = np.cumsum(np.maximum(counts - 2, 0)) - np.maximum(counts - 2, 0)
    for m in np.unique(counts[counts > 3]):
        which = np.flatnonzero(counts == m)
        rings = starts[which][:, None] + np.arange(m)
        xy, area = plane_coordinates(points[indices[rings]])
        for j in np.flatnonzero((area > 0) & ~convex(xy)):
            import mapbox_earcut
            tri = mapbox_earcut.triangulate_float64(xy[j], np.array([m], np.uint32)).reshape(-1, 3)
            if len(tri) == m - 2:                   # else (self-intersecting): the fan stays
                t0 = first_tri[which[j]]
                corner[t0:t0 + m - 2] = rings[j][tri]
    return indices[corner], corner, poly
