"""Binary PLY triangle meshes read straight from their bytes.

A mesh cache of vertex keyframes is often binary PLY (one file a frame, all
triangles). Its arrays lie in the file as they are: the header gives their
types and counts, and numpy reads them in place. Parsing that through
trimesh (or the mesh cache, which first hashes the whole file) took ~0.6 s
a 10M-triangle key, ~0.1 s this way. Anything else (ASCII, polygons that
are not triangles, texture coordinates, an element of lists between the
vertices and the faces) is left to trimesh: read_triangles returns None.
"""
import numpy as np

from raycore.jit.presets import kernel

# PLY's scalar types and numpy's
_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
          "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
          "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
# vertex properties trimesh reads as texture coordinates: left to it
_UV_NAMES = {"s", "t", "u", "v", "texture_u", "texture_v", "texture_s", "texture_t"}
_MAX_HEADER = 1 << 16


@kernel
def _triangle_rows(buf, at, count, n_vertices, faces):
    """faces from `count` face rows at buf[at:], each a one-byte count and
    three little-endian 4-byte indices (signed or not: an index of 2^31 or
    more is out of range either way); False at the first row that is not a
    triangle or names no vertex (0..n_vertices-1). One pass: numpy's
    strided copy of the 13-byte rows and its checks took ~0.3 s at 10M."""
    for r in range(count):
        p = at + 13 * r
        if buf[p] != 3:
            return False
        for k in range(3):
            q = p + 1 + 4 * k
            x = (np.int64(buf[q]) | (np.int64(buf[q + 1]) << 8) | (np.int64(buf[q + 2]) << 16)
                 | (np.int64(buf[q + 3]) << 24))
            if x >= n_vertices:
                return False
            faces[r, k] = x
    return True


def _header(data):
    """(byte order, [(element, count, [(name, dtype or (count dtype, item dtype))])],
    offset of the body), or None when this is not a binary PLY header."""
    end = data.find(b"end_header", 0, _MAX_HEADER)
    if not data.startswith(b"ply") or end < 0:
        return None
    body = data.find(b"\n", end)
    if body < 0:
        return None
    order, elements = None, []
    for raw in data[:end].decode("ascii", errors="replace").splitlines()[1:]:
        words = raw.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            if len(words) < 2 or words[1] not in ("binary_little_endian", "binary_big_endian"):
                return None
            order = "<" if words[1] == "binary_little_endian" else ">"
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements:
            if len(words) == 3 and words[1] in _TYPES:
                elements[-1][2].append((words[2], _TYPES[words[1]]))
            elif len(words) == 5 and words[1] == "list" and words[2] in _TYPES and words[3] in _TYPES:
                elements[-1][2].append((words[4], (_TYPES[words[2]], _TYPES[words[3]])))
            else:
                return None
        else:
            return None
    return (order, elements, body + 1) if order else None


def read_triangles(data):
    """(vertices (n, 3) f32, faces (m, 3) i32) of a binary PLY's bytes whose
    vertices have scalar x, y, z (and no texture coordinates) and whose
    faces are all triangles, as trimesh reads them (process=False); None
    for any other file (trimesh's to read)."""
    head = _header(data)
    if head is None:
        return None
    order, elements, at = head
    vertices = faces = None
    for name, count, props in elements:
        if name == "vertex" and vertices is None:
            if any(isinstance(t, tuple) for _, t in props) or {p for p, _ in props} & _UV_NAMES:
                return None
            dtype = np.dtype([(p, order + t) for p, t in props])
            if not {"x", "y", "z"} <= set(dtype.names or ()) or at + count * dtype.itemsize > len(data):
                return None
            if dtype == np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")]):
                vertices = np.frombuffer(data, np.float32, 3 * count, at).reshape(count, 3).copy()
            else:
                rows = np.frombuffer(data, dtype, count, at)
                vertices = np.empty((count, 3), np.float32)
                for a, p in enumerate("xyz"):
                    vertices[:, a] = rows[p]
            at += count * dtype.itemsize
        elif name == "face" and faces is None and vertices is not None:
            if len(props) != 1 or not isinstance(props[0][1], tuple):
                return None
            n_type, i_type = props[0][1]
            dtype = np.dtype([("n", order + n_type), ("v", order + i_type, (3,))])
            if at + count * dtype.itemsize > len(data):
                return None
            # other polygons (trimesh triangulates them) and indices out of
            # range (trimesh's to report): None
            if dtype == np.dtype([("n", "u1"), ("v", "<i4", (3,))]) or \
                    dtype == np.dtype([("n", "u1"), ("v", "<u4", (3,))]):
                faces = np.empty((count, 3), np.int32)
                if not _triangle_rows(np.frombuffer(data, np.uint8), at, count, len(vertices), faces):
                    return None
            else:
                rows = np.frombuffer(data, dtype, count, at)
                idx = rows["v"]
                if count and (not np.all(rows["n"] == 3) or idx.min() < 0 or idx.max() >= len(vertices)):
                    return None
                faces = np.ascontiguousarray(idx, np.int32)
            at += count * dtype.itemsize
        elif vertices is None or faces is None:
            return None                                   # an element before them: its size is unknown here
    if vertices is None or faces is None:
        return None
    return vertices, faces
