"""The one trimesh module: load a mesh file without merging or reordering."""
import numpy as np
import trimesh

from .errors import SceneError


def load_mesh(path, scene_file, key):
    """(vertices (n_v,3) f32, faces (n_t,3) i32, uvs (n_v,2) f32 or None).

    process=False keeps vertex order and count exactly as in the file, so the
    keyframes of one object stay in correspondence.
    """
    try:
        loaded = trimesh.load(str(path), process=False, force="mesh")
    except FileNotFoundError:
        raise SceneError(scene_file, key, f"mesh file not found: {path}") from None
    except Exception as exc:                       # trimesh raises many kinds
        raise SceneError(scene_file, key, f"cannot read mesh {path}: {exc}") from None
    vertices = np.ascontiguousarray(loaded.vertices, np.float32)
    faces = np.ascontiguousarray(loaded.faces, np.int32)
    if faces.size == 0:
        raise SceneError(scene_file, key, f"mesh {path} has no triangles")
    if not np.all(np.isfinite(vertices)):
        raise SceneError(scene_file, key, f"mesh {path} has non-finite vertex coordinates")
    uvs = getattr(loaded.visual, "uv", None)
    if uvs is not None and len(uvs) == len(vertices):
        uvs = np.ascontiguousarray(uvs, np.float32)
    else:
        uvs = None
    return vertices, faces, uvs
