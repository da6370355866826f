"""Parsed meshes kept on disk, keyed by the bytes they were parsed from.

A scene is rendered again and again while it is worked on; each run parsed
its mesh files with trimesh, and importing trimesh alone (it imports
scipy.spatial) took ~0.45 s of the demo's ~2 s warm start-up. A mesh parsed
once is stored as plain arrays (an uncompressed .npz) under a key that
hashes everything the parse depended on: the file's bytes, the files an OBJ
names (its MTL libraries and the textures they name, whose sizes decide a
texture atlas's UVs), the loader's version and this module's format. Any
change to any of them is a new key, so an entry is never stale; an entry
that cannot be read (cut short, foreign) is a miss and is written again.

Where: $FRUSTRACE_CACHE_DIR/meshes, else $XDG_CACHE_HOME/frustrace/meshes,
else ~/.cache/frustrace/meshes. FRUSTRACE_CACHE_DIR set to an empty string
turns the cache off. A directory that cannot be written is no error: the
mesh is parsed as before. The least recently used entries are removed once
the directory holds more than LIMIT_BYTES.
"""
import functools
import hashlib
import importlib.util
import os
import re
import tempfile
from pathlib import Path

import numpy as np

FORMAT = b"frustrace mesh cache 1"
LIMIT_BYTES = 2 << 30
# formats whose parse depends on no other file, or (OBJ) on files the key
# names; glTF, COLLADA and the like are parsed every time
CACHED_SUFFIXES = (".obj", ".stl", ".ply", ".off")
_MTLLIB = re.compile(rb"^[ \t]*mtllib[ \t]+(.+?)[ \t]*\r?$", re.MULTILINE)
_MTL_FILE = re.compile(rb"^[ \t]*(?:map_\w+|bump|disp|decal|norm|refl)[ \t]+(?:.*[ \t])?(\S+)[ \t]*\r?$",
                       re.MULTILINE)


def cache_root():
    """frustrace's cache directory (the meshes', and the workers' warm-up
    markers, anim/render/warm_lock.py), or None when it is off."""
    root = os.environ.get("FRUSTRACE_CACHE_DIR")
    if root is None:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        root = os.path.join(base, "frustrace")
    return Path(root) if root else None


def cache_dir():
    """The directory of the entries, or None when the cache is off."""
    root = cache_root()
    return root / "meshes" if root is not None else None


@functools.lru_cache(maxsize=1)
def _loader_version() -> bytes:
    """trimesh's installed version, from its dist-info directory's name
    (importlib.metadata takes ~40 ms; this is a directory listing)."""
    spec = importlib.util.find_spec("trimesh")
    if spec is None or not spec.submodule_search_locations:
        return b"no trimesh"
    site = Path(list(spec.submodule_search_locations)[0]).parent
    return ",".join(sorted(p.name for p in site.glob("trimesh-*.dist-info"))).encode() or b"trimesh ?"


def _add_file(h, path):
    h.update(str(path).encode())
    try:
        h.update(Path(path).read_bytes())
    except OSError:
        h.update(b"\0missing")


def key_of(path, data: bytes):
    """The entry's name for a mesh file of these bytes, or None if its
    format is not cached."""
    suffix = Path(path).suffix.lower()
    if suffix not in CACHED_SUFFIXES:
        return None
    h = hashlib.sha256(FORMAT)
    h.update(_loader_version())
    h.update(suffix.encode())
    h.update(len(data).to_bytes(8, "little"))
    h.update(data)
    if suffix == ".obj":
        folder = Path(path).parent
        for name in _MTLLIB.findall(data):
            mtl = folder / name.decode(errors="replace")
            _add_file(h, mtl)
            try:
                mtl_text = mtl.read_bytes()
            except OSError:
                continue
            for tex in _MTL_FILE.findall(mtl_text):
                _add_file(h, mtl.parent / tex.decode(errors="replace"))
    return h.hexdigest()


def load(key):
    """(vertices, faces, uvs or None) stored under key, or None."""
    folder = cache_dir()
    if key is None or folder is None:
        return None
    path = folder / f"{key}.npz"
    try:
        with np.load(path, allow_pickle=False) as entry:
            vertices, faces = entry["vertices"], entry["faces"]
            uvs = entry["uvs"] if "uvs" in entry.files else None
    except Exception:                               # absent, cut short, foreign: a miss
        return None
    try:
        os.utime(path)                              # recently used: pruned last
    except OSError:                                 # a cache shared read-only: still a hit
        pass
    if vertices.dtype != np.float32 or faces.dtype != np.int32 or vertices.ndim != 2 or faces.ndim != 2:
        return None
    return vertices, faces, uvs


def store(key, vertices, faces, uvs):
    """Write an entry (atomically: a reader sees the whole file or none)."""
    folder = cache_dir()
    if key is None or folder is None:
        return
    arrays = {"vertices": vertices, "faces": faces}
    if uvs is not None:
        arrays["uvs"] = uvs
    tmp = None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, suffix=".tmp", delete=False) as f:
            tmp = f.name
            np.savez(f, **arrays)
        os.replace(tmp, folder / f"{key}.npz")
        tmp = None
        _prune(folder)
    except OSError:
        pass                                        # read-only or full: parse next time too
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass


def _prune(folder, limit=None):
    """Remove the least recently used entries while the folder holds more
    than limit bytes (LIMIT_BYTES)."""
    limit = LIMIT_BYTES if limit is None else limit
    entries = []
    for p in folder.glob("*.npz"):
        try:
            st = p.stat()
        except OSError:
            continue
        entries.append((st.st_mtime_ns, st.st_size, p))
    total = sum(size for _, size, _ in entries)
    for _, size, p in sorted(entries):
        if total <= limit:
            break
        try:
            p.unlink()
        except OSError:
            pass
        total -= size
