"""Binary triangle PLYs read straight from their bytes (anim/io/ply.py)
give what trimesh gives for the same file, bit for bit; every other PLY is
left to trimesh (read_triangles returns None), and a scene loads the same
either way."""
import numpy as np
import pytest

from anim.io import ply
from anim.io.mesh_io import _parse, load_mesh


def _write(path, vertices, faces, *, order="<", vtypes=("float",) * 3, extra=(), count_type="uchar",
           index_type="int", counts=None, fmt=None, before=b"", after=b""):
    """A PLY of these vertices (x, y, z as vtypes, then the `extra` float
    properties, random) and faces (each row's count from counts, default 3)."""
    np_types = {"float": "f4", "double": "f8", "int": "i4", "uint": "u4", "uchar": "u1", "ushort": "u2",
                "short": "i2"}
    fmt = fmt or ("binary_little_endian" if order == "<" else "binary_big_endian")
    head = [b"ply", f"format {fmt} 1.0".encode(), b"comment made by a test", before.rstrip(b"\n")]
    head.append(f"element vertex {len(vertices)}".encode())
    head += [f"property {t} {n}".encode() for t, n in zip(vtypes, "xyz")]
    head += [f"property float {n}".encode() for n in extra]
    head += [f"element face {len(faces)}".encode(),
             f"property list {count_type} {index_type} vertex_indices".encode()]
    head += [after.rstrip(b"\n"), b"end_header"]
    vdt = np.dtype([(n, order + np_types[t]) for t, n in zip(vtypes, "xyz")] + [(n, order + "f4") for n in extra])
    vrows = np.zeros(len(vertices), vdt)
    for a, n in enumerate("xyz"):
        vrows[n] = vertices[:, a]
    for n in extra:
        vrows[n] = np.linspace(0, 1, len(vertices))
    width = faces.shape[1]
    fdt = np.dtype([("n", order + np_types[count_type]), ("v", order + np_types[index_type], (width,))])
    frows = np.zeros(len(faces), fdt)
    frows["n"] = width if counts is None else counts
    frows["v"] = faces
    path.write_bytes(b"\n".join(h for h in head if h) + b"\n" + vrows.tobytes() + frows.tobytes())
    return path


def _mesh(rng, n_v=300, n_t=500):
    vertices = (rng.normal(size=(n_v, 3)) * np.float32(3)).astype(np.float32)
    vertices[0] = (1e-40, -0.0, 3e38)                     # a denormal, a signed zero, near the float range's end
    return vertices, rng.integers(0, n_v, size=(n_t, 3)).astype(np.int32)


@pytest.mark.parametrize("variant", [
    {}, {"order": ">"}, {"vtypes": ("double",) * 3}, {"extra": ("nx", "ny", "nz", "red")},
    {"index_type": "uint"}, {"count_type": "int"}, {"index_type": "ushort"},
    {"after": b"element edge 0\nproperty int vertex1\n"}])
def test_a_binary_triangle_ply_reads_as_trimesh_reads_it(tmp_path, rng, variant):
    vertices, faces = _mesh(rng)
    path = _write(tmp_path / "m.ply", vertices, faces, **variant)
    got = ply.read_triangles(path.read_bytes())
    assert got is not None, variant
    want_v, want_f, want_uv = _parse(path, "anim.yaml", "mesh")
    assert want_uv is None
    assert got[0].dtype == np.float32 and got[1].dtype == np.int32
    assert np.array_equal(got[0].view(np.uint32), want_v.view(np.uint32))
    assert np.array_equal(got[1], want_f)
    assert np.array_equal(got[1], faces)


@pytest.mark.parametrize("variant", [
    {"fmt": "ascii"}, {"extra": ("s", "t")}, {"extra": ("texture_u", "texture_v")},
    {"before": b"element material 1\nproperty list uchar int names\n"}, {"index_type": "short"}])
def test_other_plys_are_left_to_trimesh(tmp_path, rng, variant):
    vertices, faces = _mesh(rng)
    if variant.get("fmt") == "ascii":
        import trimesh
        path = tmp_path / "m.ply"
        path.write_bytes(trimesh.exchange.ply.export_ply(trimesh.Trimesh(vertices, faces, process=False),
                                                         encoding="ascii"))
    else:
        if "index_type" in variant:                       # indices as they would wrap: trimesh's to report
            faces[0, 0] = -1
        path = _write(tmp_path / "m.ply", vertices, faces, **variant)
    assert ply.read_triangles(path.read_bytes()) is None


def test_polygons_and_stray_indices_are_left_to_trimesh(tmp_path, rng):
    vertices, faces = _mesh(rng)
    quads = np.concatenate([faces, faces[:, :1]], axis=1)
    counts = np.full(len(faces), 4)
    assert ply.read_triangles(_write(tmp_path / "q.ply", vertices, quads, counts=counts).read_bytes()) is None
    mixed = quads.copy()
    counts[1:] = 3                                        # the rows' sizes disagree with a triangle's
    assert ply.read_triangles(_write(tmp_path / "x.ply", vertices, mixed, counts=counts).read_bytes()) is None
    for bad in (-1, len(vertices)):
        stray = faces.copy()
        stray[7, 2] = bad
        assert ply.read_triangles(_write(tmp_path / "s.ply", vertices, stray).read_bytes()) is None
    data = _write(tmp_path / "cut.ply", vertices, faces).read_bytes()
    assert ply.read_triangles(data[:-5]) is None          # cut short
    assert ply.read_triangles(b"solid x\n" + data) is None


def test_a_scene_loads_a_ply_key_as_before(tmp_path, rng, monkeypatch):
    """load_mesh through the direct read and through trimesh (the direct
    read turned off): the same arrays; and its checks are the same."""
    from anim.errors import SceneError
    vertices, faces = _mesh(rng)
    path = _write(tmp_path / "k.ply", vertices, faces)
    direct = load_mesh(path, "anim.yaml", "objects[0].keyframes[0].mesh")
    monkeypatch.setenv("FRUSTRACE_CACHE_DIR", "")
    monkeypatch.setattr(ply, "read_triangles", lambda data: None)
    parsed = load_mesh(path, "anim.yaml", "objects[0].keyframes[0].mesh")
    assert all(np.array_equal(a, b) for a, b in zip(direct[:2], parsed[:2])) and direct[2] is parsed[2] is None
    monkeypatch.undo()
    vertices[3, 1] = np.nan
    with pytest.raises(SceneError, match="non-finite"):
        load_mesh(_write(tmp_path / "nan.ply", vertices, faces), "anim.yaml", "mesh")
    with pytest.raises(SceneError, match="no triangles"):
        load_mesh(_write(tmp_path / "none.ply", vertices, faces[:0]), "anim.yaml", "mesh")
