"""Per-frame triangle preparation: gather vertex triples, vertex normals.

`tri_verts` (n_tris, 9) float32 holds v0, v1, v2 of each triangle contiguously
(36 bytes, one cache line) so that traversal never chases face indices.
"""
import numpy as np

from raycore.jit.presets import helper, kernel, parallel_arith_kernel
from numba import prange


@parallel_arith_kernel
def gather_triangles(vertices, faces, tri_verts):
    """vertices (n_v, 3) f32, faces (n_t, 3) i32 -> tri_verts (n_t, 9) f32."""
    for t in prange(faces.shape[0]):
        for k in range(3):
            v = faces[t, k]
            tri_verts[t, 3 * k + 0] = vertices[v, 0]
            tri_verts[t, 3 * k + 1] = vertices[v, 1]
            tri_verts[t, 3 * k + 2] = vertices[v, 2]


@parallel_arith_kernel
def gather_some_triangles(vertices, faces, ids, tri_verts, packed):
    """Re-gather only triangles `ids` into tri_verts, and also pack them
    contiguously into packed (len(ids), 9): the moving part of a scene."""
    for i in prange(ids.shape[0]):
        t = ids[i]
        for k in range(3):
            v = faces[t, k]
            for a in range(3):
                x = vertices[v, a]
                tri_verts[t, 3 * k + a] = x
                packed[i, 3 * k + a] = x


def vertex_face_csr(faces: np.ndarray, n_vertices: int):
    """Vertex -> incident faces as CSR (start (n_v+1,), faces (3 n_t,)) int32.

    Built once per topology; lets normals be gathered per vertex in parallel
    without atomics.
    """
    start = np.zeros(n_vertices + 1, np.int32)
    incident = np.empty(faces.size, np.int32)
    _fill_csr(np.ascontiguousarray(faces, np.int32), start, incident, np.empty(n_vertices, np.int32))
    return start, incident


@kernel
def _fill_csr(faces, start, incident, cursor):
    """A counting sort of the faces by vertex, each vertex's in increasing
    order (as a stable argsort of the corners gives them) without its
    int64 copies (720 MB at 10M triangles)."""
    for t in range(faces.shape[0]):
        for k in range(3):
            start[faces[t, k] + 1] += 1
    for v in range(cursor.shape[0]):
        start[v + 1] += start[v]
        cursor[v] = start[v]
    for t in range(faces.shape[0]):
        for k in range(3):
            v = faces[t, k]
            incident[cursor[v]] = t
            cursor[v] += 1


@parallel_arith_kernel
def vertex_normals(tri_verts, vf_start, vf_faces, normals):
    """Area-weighted vertex normals (n_v, 3) f32 from triangle vertices."""
    for v in prange(normals.shape[0]):
        _vertex_normal(tri_verts, vf_start, vf_faces, normals, v)


@parallel_arith_kernel
def vertex_normals_of(ids, tri_verts, vf_start, vf_faces, normals):
    """vertex_normals for the vertices `ids` only (the moving ones)."""
    for i in prange(ids.shape[0]):
        _vertex_normal(tri_verts, vf_start, vf_faces, normals, ids[i])


@parallel_arith_kernel
def mark_hit_vertices(prim, faces, state, vertices, tri_verts, gather):
    """state[v] = 1 (wanted) for the vertices of the hit triangles prim (-1:
    a miss) whose normal is not made yet (state 0). Threads may mark one
    vertex at once: they write the same byte. With gather, each hit
    triangle's corners are also copied from the vertices into tri_verts[t]
    (the rows a pass's shading reads, when the frame's corners were not
    all gathered: FrameStructures.build), in the same pass over the hits."""
    for i in prange(prim.shape[0]):
        t = prim[i]
        if t >= 0:
            for k in range(3):
                v = faces[t, k]
                if state[v] == 0:
                    state[v] = 1
                if gather:
                    for a in range(3):
                        tri_verts[t, 3 * k + a] = vertices[v, a]


@parallel_arith_kernel
def wanted_vertex_normals(state, vertices, faces, vf_start, vf_faces, normals):
    """vertex_normals for the vertices marked wanted (state 1), then made (2):
    the same normals, bit for bit, for the vertices that are seen, their
    triangles' corners read from the vertices through the faces (the frame's
    corners, tri_verts, are not gathered when only seen triangles need
    them: FrameStructures.build)."""
    for v in prange(state.shape[0]):
        if state[v] == 1:
            nx = 0.0
            ny = 0.0
            nz = 0.0
            for j in range(vf_start[v], vf_start[v + 1]):
                f = vf_faces[j]
                a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
                cx, cy, cz = _face_cross(vertices[a, 0], vertices[a, 1], vertices[a, 2], vertices[b, 0],
                                         vertices[b, 1], vertices[b, 2], vertices[c, 0], vertices[c, 1],
                                         vertices[c, 2])
                nx += cx
                ny += cy
                nz += cz
            _store_unit(normals, v, nx, ny, nz)
            state[v] = 2


@helper
def _face_cross(x0, y0, z0, x1, y1, z1, x2, y2, z2):
    """(p1 - p0) x (p2 - p0) in float32: twice the triangle's area along its normal."""
    e1x = x1 - x0
    e1y = y1 - y0
    e1z = z1 - z0
    e2x = x2 - x0
    e2y = y2 - y0
    e2z = z2 - z0
    return e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x


@helper
def _store_unit(normals, v, nx, ny, nz):
    """normals[v] = (nx, ny, nz) made unit length (left as is when zero)."""
    length = np.sqrt(nx * nx + ny * ny + nz * nz)
    if length > 0.0:
        nx /= length
        ny /= length
        nz /= length
    normals[v, 0] = nx
    normals[v, 1] = ny
    normals[v, 2] = nz


@helper
def _vertex_normal(tri_verts, vf_start, vf_faces, normals, v):
    """Area-weighted normal of vertex v from its incident triangles."""
    nx = 0.0
    ny = 0.0
    nz = 0.0
    for j in range(vf_start[v], vf_start[v + 1]):
        p = tri_verts[vf_faces[j]]
        cx, cy, cz = _face_cross(p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8])
        nx += cx
        ny += cy
        nz += cz
    _store_unit(normals, v, nx, ny, nz)
