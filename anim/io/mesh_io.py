"""The one trimesh module: load a mesh file without merging or reordering.

STL is the exception: it stores every triangle's three corners apart, so
nothing is shared and vertex normals would be the facets' own (a faceted
look). Its exactly coincident corners are merged, in order of first
appearance, so that keyframes of one STL animation stay in correspondence.
trimesh is imported only to parse a file that anim/io/mesh_cache.py has not kept
(importing it, with scipy.spatial, costs ~0.45 s).
"""
import numpy as np

from anim.io import mesh_cache, ply
from anim.errors import SceneError


def load_mesh(path, scene_file, key):
    """(vertices (n_v,3) f32, faces (n_t,3) i32, uvs (n_v,2) f32 or None).

    process=False keeps vertex order and count exactly as in the file, so the
    keyframes of one object stay in correspondence.
    """
    try:
        data = open(path, "rb").read()
    except FileNotFoundError:
        raise SceneError(scene_file, key, f"mesh file not found: {path}") from None
    except OSError as exc:
        raise SceneError(scene_file, key, f"cannot read mesh {path}: {exc}") from None
    if str(path).lower().endswith(".ply"):
        direct = ply.read_triangles(data)     # a binary triangle PLY: its arrays as they lie
        if direct is not None:
            _check(*direct, path, scene_file, key)
            return (*direct, None)
    cache_key = mesh_cache.key_of(path, data)
    cached = mesh_cache.load(cache_key)
    if cached is not None:
        return cached
    vertices, faces, uvs = _parse(path, scene_file, key)
    mesh_cache.store(cache_key, vertices, faces, uvs)
    return vertices, faces, uvs


def _check(vertices, faces, path, scene_file, key):
    """SceneError for a mesh without triangles or with coordinates that are not finite."""
    if faces.size == 0:
        raise SceneError(scene_file, key, f"mesh {path} has no triangles")
    if not np.all(np.isfinite(vertices)):
        raise SceneError(scene_file, key, f"mesh {path} has non-finite vertex coordinates")


def _parse(path, scene_file, key):
    """load_mesh's result, parsed by trimesh and checked."""
    import trimesh
    try:
        loaded = trimesh.load(str(path), process=False, force="mesh")
    except FileNotFoundError:
        raise SceneError(scene_file, key, f"mesh file not found: {path}") from None
    except Exception as exc:                       # trimesh raises many kinds
        raise SceneError(scene_file, key, f"cannot read mesh {path}: {exc}") from None
    vertices = np.ascontiguousarray(loaded.vertices, np.float32)
    faces = np.ascontiguousarray(loaded.faces, np.int32)
    _check(vertices, faces, path, scene_file, key)
    if str(path).lower().endswith(".stl"):
        vertices, faces = merge_coincident(vertices, faces)
    uvs = getattr(loaded.visual, "uv", None)
    if uvs is not None and len(uvs) == len(vertices):
        uvs = np.ascontiguousarray(uvs, np.float32)
    else:
        uvs = None
    return vertices, faces, uvs


def merge_coincident(vertices, faces):
    """Vertices with identical coordinates made one, kept in order of first
    appearance; faces re-indexed."""
    _, first, inverse = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    return (np.ascontiguousarray(vertices[np.sort(first)]),
            np.ascontiguousarray(rank[inverse.reshape(-1)][faces], np.int32))


def vertex_lines(path) -> int:
    """How many vertices an OBJ file writes ('v ' lines), counted as
    written: the loader drops vertices no face uses, which would hide an
    extra or missing line that shifts every index after it. -1 if the file
    cannot be read."""
    try:
        data = open(path, "rb").read()
    except OSError:
        return -1
    return (data.count(b"\nv ") + data.count(b"\nv\t")
            + (data[:2] in (b"v ", b"v\t")))
