"""anim/io/mesh_cache.py: a mesh loaded from the cache is the mesh trimesh
parses (the oracle: mesh_io._parse), and every change to what the parse read
gives a new entry."""
import os
import subprocess
import sys

import numpy as np
import pytest

from anim.io import mesh_cache
from anim.io import mesh_io
from conftest import ROOT

OBJ_TWO_MATERIALS = """mtllib two.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vt 0.5 0.5
usemtl red
f 1/1 2/2 3/3
f 1/1 3/3 4/4
usemtl blue
f 2/5 5/2 3/3
"""
MTL = "newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\nmap_Kd tex.png\n"


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("FRUSTRACE_CACHE_DIR", str(folder))
    return folder / "meshes"


def _write_meshes(folder):
    """An OBJ with UVs and two materials (its MTL names a texture), an STL
    and a PLY: the formats the cache keeps."""
    import trimesh
    (folder / "two.obj").write_text(OBJ_TWO_MATERIALS)
    (folder / "two.mtl").write_text(MTL)
    (folder / "tex.png").write_bytes(bytes.fromhex(
        "89504e470d0a1a0a0000000d4948445200000001000000010802000000907753de0000000c4944415408d763f8cf"
        "c000000301010018dd8db00000000049454e44ae426082"))
    box = trimesh.creation.box()
    box.export(folder / "box.stl")
    box.export(folder / "box.ply")
    return ["two.obj", "box.stl", "box.ply"]


def _same(a, b):
    assert np.array_equal(a[0], b[0]) and a[0].dtype == b[0].dtype == np.float32
    assert np.array_equal(a[1], b[1]) and a[1].dtype == b[1].dtype == np.int32
    assert (a[2] is None) == (b[2] is None)
    if a[2] is not None:
        assert np.array_equal(a[2], b[2])


def test_a_cached_mesh_is_the_mesh_trimesh_parses(tmp_path, cache, monkeypatch):
    for name in _write_meshes(tmp_path):
        path = tmp_path / name
        parsed = mesh_io._parse(path, "s.yaml", "objects.0.mesh")
        first = mesh_io.load_mesh(path, "s.yaml", "objects.0.mesh")        # a miss: parsed, stored
        _same(first, parsed)
        with monkeypatch.context() as m:
            m.setattr(mesh_io, "_parse", lambda *a: pytest.fail("a cached mesh was parsed again"))
            _same(mesh_io.load_mesh(path, "s.yaml", "objects.0.mesh"), parsed)
    # the OBJ's and the STL's: the binary PLY is read straight from its bytes (anim/io/ply.py)
    assert len(list(cache.glob("*.npz"))) == 2


def test_the_obj_keeps_its_uvs_through_the_cache(tmp_path, cache):
    _write_meshes(tmp_path)
    mesh_io.load_mesh(tmp_path / "two.obj", "s.yaml", "k")
    v, f, uv = mesh_io.load_mesh(tmp_path / "two.obj", "s.yaml", "k")
    assert uv is not None and uv.shape == (len(v), 2)


def test_an_edited_mesh_is_parsed_again(tmp_path, cache):
    path = tmp_path / "t.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    mesh_io.load_mesh(path, "s.yaml", "k")
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 2 0\nf 1 2 3\n")
    v, _, _ = mesh_io.load_mesh(path, "s.yaml", "k")
    assert v[2, 1] == 2.0


def test_the_key_covers_the_mtl_and_its_textures(tmp_path):
    _write_meshes(tmp_path)
    data = (tmp_path / "two.obj").read_bytes()
    keys = {mesh_cache.key_of(tmp_path / "two.obj", data)}
    (tmp_path / "two.mtl").write_text(MTL.replace("Kd 1 0 0", "Kd 1 1 0"))
    keys.add(mesh_cache.key_of(tmp_path / "two.obj", data))
    (tmp_path / "tex.png").write_bytes(b"another image")
    keys.add(mesh_cache.key_of(tmp_path / "two.obj", data))
    (tmp_path / "tex.png").unlink()
    keys.add(mesh_cache.key_of(tmp_path / "two.obj", data))
    assert len(keys) == 4
    assert mesh_cache.key_of(tmp_path / "scene.gltf", b"{}") is None      # not cached: names other files


def test_a_broken_entry_is_a_miss_and_written_again(tmp_path, cache):
    path = tmp_path / "t.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    expected = mesh_io._parse(path, "s.yaml", "k")
    mesh_io.load_mesh(path, "s.yaml", "k")
    (entry,) = cache.glob("*.npz")
    entry.write_bytes(entry.read_bytes()[:40])                 # cut short
    _same(mesh_io.load_mesh(path, "s.yaml", "k"), expected)
    assert mesh_cache.load(entry.stem) is not None              # whole again


def test_a_cache_that_cannot_be_written_is_no_error(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("FRUSTRACE_CACHE_DIR", str(blocker))
    path = tmp_path / "t.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    for _ in range(2):
        _same(mesh_io.load_mesh(path, "s.yaml", "k"), mesh_io._parse(path, "s.yaml", "k"))
    assert not list(tmp_path.glob("*.tmp")) and not list(tmp_path.glob("**/*.tmp"))


def test_an_empty_cache_dir_setting_turns_the_cache_off(tmp_path, monkeypatch):
    monkeypatch.setenv("FRUSTRACE_CACHE_DIR", "")
    assert mesh_cache.cache_dir() is None
    path = tmp_path / "t.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    mesh_io.load_mesh(path, "s.yaml", "k")
    assert list(tmp_path.iterdir()) == [path]


def test_bad_meshes_are_refused_and_not_kept(tmp_path, cache):
    from anim.errors import SceneError
    path = tmp_path / "nan.obj"
    path.write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    for _ in range(2):
        with pytest.raises(SceneError, match="non-finite"):
            mesh_io.load_mesh(path, "s.yaml", "k")
    with pytest.raises(SceneError, match="not found"):
        mesh_io.load_mesh(tmp_path / "absent.obj", "s.yaml", "k")
    assert not cache.exists() or not list(cache.glob("*.npz"))


def test_pruning_removes_the_least_recently_used_first(tmp_path):
    for i, name in enumerate(["old", "mid", "new"]):
        p = tmp_path / f"{name}.npz"
        p.write_bytes(b"x" * 100)
        os.utime(p, ns=(i * 10**9, i * 10**9))
    mesh_cache._prune(tmp_path, limit=250)
    assert sorted(p.stem for p in tmp_path.glob("*.npz")) == ["mid", "new"]


@pytest.mark.parametrize("text", ["v 0 0 0\nvt 0 0\nv 1 1 1\n", "v\t1 2 3\r\nvn 0 0 1\r\nv 1 2 3\r\n",
                                  "# c\nv 1 2 3", "", "vv 1\n v 2 3 4\nv 1 1 1\n"])
def test_vertex_lines_counts_the_v_lines_as_written(tmp_path, text):
    path = tmp_path / "m.obj"
    path.write_text(text, newline="")
    with open(path, "rb") as f:
        expected = sum(line[:2] in (b"v ", b"v\t") for line in f)
    assert mesh_io.vertex_lines(path) == expected
    assert mesh_io.vertex_lines(tmp_path / "absent.obj") == -1


def test_a_warm_demo_start_imports_neither_trimesh_nor_scipy_spatial(tmp_path):
    """What the cache (and the slerped tracks' numba path) are for: a scene
    loaded and placed at a time without the two slow imports."""
    code = ("import sys; sys.path.insert(0, %r)\n"
            "from anim.scene import AnimatedScene\n"
            "s = AnimatedScene(%r); s.vertices_at(0.3)\n"
            "print(sorted(m for m in ('trimesh', 'scipy.spatial') if m in sys.modules))\n"
            % (str(ROOT), str(ROOT / "anim/builtin/demo/anim.yaml")))
    env = {**os.environ, "FRUSTRACE_CACHE_DIR": str(tmp_path)}
    cold = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    warm = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert "trimesh" in cold.stdout                    # parsed once (trimesh brings scipy.spatial)
    assert warm.stdout.strip() == "[]"


def test_a_read_only_cache_still_hits(tmp_path, cache, monkeypatch):
    """A cache shared read-only (its entries' times cannot be touched) is
    still read, not parsed around."""
    path = tmp_path / "t.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    mesh_io.load_mesh(path, "s.yaml", "k")

    def refuse(*args, **kwargs):
        raise PermissionError("read-only")
    monkeypatch.setattr(os, "utime", refuse)
    monkeypatch.setattr(mesh_io, "_parse", lambda *a: pytest.fail("a cached mesh was parsed again"))
    v, f, _ = mesh_io.load_mesh(path, "s.yaml", "k")
    assert v.shape == (3, 3) and f.shape == (1, 3)
