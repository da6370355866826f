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
def mark_hit_vertices(prim, faces, state):
    """state[v] = 1 (wanted) for the vertices of the hit triangles prim (-1:
    a miss) whose normal is not made yet (state 0). Threads may mark one
    vertex at once: they write the same byte."""
    for i in prange(prim.shape[0]):
        t = prim[i]
        if t >= 0:
            for k in range(3):
                v = faces[t, k]
                if state[v] == 0:
                    state[v] = 1


@parallel_arith_kernel
def wanted_vertex_normals(state, tri_verts, vf_start, vf_faces, normals):
    """vertex_normals for the vertices marked wanted (state 1), then made (2):
    the same normals, bit for bit, for the vertices that are seen."""
    for v in prange(state.shape[0]):
        if state[v] == 1:
            _vertex_normal(tri_verts, vf_start, vf_faces, normals, v)
            state[v] = 2


@helper
def _vertex_normal(tri_verts, vf_start, vf_faces, normals, v):
    """Area-weighted normal of vertex v from its incident triangles."""
    nx = 0.0
    ny = 0.0
    nz = 0.0
    for j in range(vf_start[v], vf_start[v + 1]):
        p = tri_verts[vf_faces[j]]
        e1x = p[3] - p[0]
        e1y = p[4] - p[1]
        e1z = p[5] - p[2]
        e2x = p[6] - p[0]
        e2y = p[7] - p[1]
        e2z = p[8] - p[2]
        nx += e1y * e2z - e1z * e2y
        ny += e1z * e2x - e1x * e2z
        nz += e1x * e2y - e1y * e2x
    length = np.sqrt(nx * nx + ny * ny + nz * nz)
    if length > 0.0:
        nx /= length
        ny /= length
        nz /= length
    normals[v, 0] = nx
    normals[v, 1] = ny
    normals[v, 2] = nz
