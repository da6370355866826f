"""The triangles a pass of camera rays sees in an instanced world, placed in
the world: one per hit pixel, so that the visible-surface gather
(shading/surface.py) and everything after it run as they do on a flat
scene, never asking which instance a hit was in.

Slot i holds pixel i's hit triangle (its corners under the instance's
transform, its vertex normals under the inverse transpose, its UVs and
material): the gather's triangle i, with faces (3i, 3i + 1, 3i + 2). A
world triangle (the identity) is copied bit for bit, so a scene's
non-instanced objects shade exactly as in a flat scene.
"""
import numba
import numpy as np

from raycore.jit.presets import parallel_kernel

INT32_MAX = 2 ** 31 - 1


@parallel_kernel
def place_seen(prim, inst, tri_verts, faces, normals, uvs, tri_material, tri_shift, plain, forward, inverse,
               identity, inst_material, id_base, out_verts, out_vertices, out_normals, out_uvs, out_material, out_prim, out_id):
    """Slot i of every hit pixel i (prim[i] >= 0, in instance inst[i]):
    out_verts (n, 9), out_vertices and out_normals (3n, 3), out_uvs (3n, 2)
    when uvs has rows, out_material (n,): the instance's material where it
    has one and the triangle is `plain`, else the triangle's; out_prim[i] = i (-1 on a miss),
    out_id[i] the primitive's id in the flattened world (int32, saturated)."""
    with_uv = uvs.shape[0] > 0
    for i in numba.prange(prim.shape[0]):
        k = prim[i]
        if k < 0:
            out_prim[i] = -1
            continue
        j = inst[i]
        out_prim[i] = i
        m = forward[j]
        q = inverse[j]          # normals go by its transpose
        same = identity[j]
        for c in range(3):
            x, y, z = tri_verts[k, 3 * c], tri_verts[k, 3 * c + 1], tri_verts[k, 3 * c + 2]
            v = faces[k, c]
            nx, ny, nz = normals[v, 0], normals[v, 1], normals[v, 2]
            if not same:
                x, y, z = (m[0] * x + m[1] * y + m[2] * z + m[3], m[4] * x + m[5] * y + m[6] * z + m[7],
                           m[8] * x + m[9] * y + m[10] * z + m[11])
                nx, ny, nz = (q[0] * nx + q[4] * ny + q[8] * nz, q[1] * nx + q[5] * ny + q[9] * nz,
                              q[2] * nx + q[6] * ny + q[10] * nz)
                length = np.sqrt(nx * nx + ny * ny + nz * nz)
                if length > 0:
                    nx, ny, nz = nx / length, ny / length, nz / length
            out_verts[i, 3 * c], out_verts[i, 3 * c + 1], out_verts[i, 3 * c + 2] = x, y, z
            s = 3 * i + c
            out_vertices[s, 0], out_vertices[s, 1], out_vertices[s, 2] = x, y, z
            out_normals[s, 0], out_normals[s, 1], out_normals[s, 2] = nx, ny, nz
            if with_uv:
                out_uvs[s, 0], out_uvs[s, 1] = uvs[v, 0], uvs[v, 1]
        mat = inst_material[j]
        out_material[i] = mat if (mat >= 0 and plain[k]) else tri_material[k]
        out_id[i] = min(id_base[j] + k + tri_shift[k], INT32_MAX)


class SeenTriangles:
    """Work arrays for the seen triangles of one image size, kept from pass
    to pass (fresh large arrays cost page faults every frame)."""

    def __init__(self, n_pix, textured):
        self.verts = np.empty((n_pix, 9), np.float32)
        self.vertices = np.empty((3 * n_pix, 3), np.float32)
        self.normals = np.empty((3 * n_pix, 3), np.float32)
        self.uvs = np.empty((3 * n_pix if textured else 0, 2), np.float32)
        self.material = np.empty(n_pix, np.int32)
        self.prim = np.empty(n_pix, np.int32)
        self.ids = np.empty(n_pix, np.int32)
        self.faces = np.arange(3 * n_pix, dtype=np.int32).reshape(n_pix, 3)

    def place(self, prim, inst, tri_verts, faces, normals, uvs, tri_material, tri_shift, plain, place):
        """Slots for hits (prim, inst) of one pass (prim -1: a miss):
        (prim of the slots, verts, faces, normals, material, uvs)."""
        n = prim.shape[0]
        plain = np.zeros(tri_material.shape[0], np.bool_) if plain is None else plain
        place_seen(prim, inst, tri_verts, faces, normals, uvs, tri_material, tri_shift, plain, place.forward,
                   place.inverse,
                   place.identity, place.material, place.id_base, self.verts[:n], self.vertices[:3 * n],
                   self.normals[:3 * n], self.uvs[:3 * n], self.material[:n], self.prim[:n], self.ids[:n])
        return self.prim[:n], self.verts[:n], self.faces[:n], self.normals[:3 * n], self.material[:n], \
            self.uvs[:3 * n]
