"""The visible-surface gather (raycore/shading/surface.py, whose row loop LLVM
vectorizes) against its definitions written out in float64 numpy, on made-up
hits: random triangles with degenerate ones among them (a point, a line),
vertex normals that cancel (the smooth normal falls back to the geometric
one), textured and flat materials, smooth and flat facets, and an image
whose blocks are part empty. The hits are scattered (each pixel its own
triangle: every untextured sample takes fill_block's gathered loop) or in
runs along the rows, long and short, so that blocks take its run loop and
its gathered loop both."""
import numpy as np
import pytest

from oracles import camera_rays
from test_shade import _bilinear


def _mesh(rng, n_t=300):
    verts = rng.normal(0, 1, (3 * n_t, 3)).astype(np.float32) * np.float32(4)
    faces = np.arange(3 * n_t, dtype=np.int32).reshape(n_t, 3)
    verts[faces[0]] = verts[faces[0, 0]]                            # a point
    verts[faces[1, 2]] = verts[faces[1, 0]]                       # a line (two corners the same)
    normals = rng.normal(0, 1, verts.shape)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[faces[2, 1]] = -normals[faces[2, 0]]                   # cancel at (1/2, 1/2, 0)
    normals[faces[2, 2]] = normals[faces[2, 0]]
    return verts, faces, normals.astype(np.float32)


def _oracle(cam, w, h, prim, b1, b2, t, verts, faces, normals, smooth, materials, tri_material, uvs, tex):
    tv = verts[faces].astype(np.float64)                          # (n_t, 3, 3)
    _, d = camera_rays(cam, w, h)
    view = d.astype(np.float64)
    hit = np.nonzero(prim >= 0)[0]
    out = {k: [] for k in ("pixel", "point", "lifted", "geo_n", "smooth_n", "view", "depth", "mag", "albedo")}
    for p in hit:
        k = prim[p]
        b = np.array([1 - b1[p] - b2[p], b1[p], b2[p]], np.float64)
        pt = b @ tv[k]
        g = np.cross(tv[k, 1] - tv[k, 0], tv[k, 2] - tv[k, 0])
        gl = np.linalg.norm(g)
        g = g / gl if gl > 0 else np.zeros(3)
        side = -1.0 if g @ view[p] > 0 else 1.0
        g = side * g
        lifted, sn = pt.copy(), np.zeros(3)
        if smooth:
            n = side * normals[faces[k]].astype(np.float64)
            lifted = pt - sum(b[i] * min((pt - tv[k, i]) @ n[i], 0.0) * n[i] for i in range(3))
            sn = b @ n
        sl = np.linalg.norm(sn)
        sn = sn / sl if sl > 0 else g
        mat = materials[tri_material[k]].astype(np.float64)
        albedo = mat[:3].copy()
        if mat[5] >= 0 and smooth:
            uv = b @ uvs[faces[k]].astype(np.float64)
            albedo *= _bilinear(tex.astype(np.float64), np.array([uv[0]]), np.array([uv[1]]))[0]
        out["pixel"].append(p)
        out["point"].append(pt)
        out["lifted"].append(lifted)
        out["geo_n"].append(g)
        out["smooth_n"].append(sn)
        out["view"].append(view[p])
        out["depth"].append(t[p] * (view[p] @ np.asarray(cam[3:6], np.float64)))
        out["mag"].append(max(np.abs(tv[k]).max(), np.abs(lifted).max()))
        out["albedo"].append(albedo)
    return {k: np.array(v) for k, v in out.items()}


def _runs(rng, w, h, n_t):
    """Triangles in runs along the rows: long runs (8-40 pixels) in the top
    rows, long and short (1-3) mixed in the middle ones, short ones below."""
    prim = np.empty((h, w), np.int32)
    for y in range(h):
        x = 0
        while x < w:
            long_run = y < 12 or (y < 32 and rng.random() < 0.5)
            length = rng.integers(8, 41) if long_run else rng.integers(1, 4)
            prim[y, x:x + length] = rng.integers(0, n_t)
            x += length
    prim[:3, :30] = np.arange(3)[:, None]                            # the degenerate triangles in runs
    return prim.reshape(-1)


def _block_paths(prim, w, h):
    """(blocks of long runs, which fill_block's run loop takes, their runs
    shorter than LONG_RUN, blocks whose untextured runs are all gathered)."""
    from raycore.config import GATHER_BLOCK, LONG_RUN, RUN_BLOCK
    img = prim.reshape(h, w)
    run_blocks = short_runs = gathered_blocks = 0
    for y0 in range(0, h, GATHER_BLOCK):
        for x0 in range(0, w, GATHER_BLOCK):
            v = img[y0:y0 + GATHER_BLOCK, x0:x0 + GATHER_BLOCK]
            v = v[v >= 0]
            if v.size == 0:
                continue
            lengths = np.diff(np.r_[0, np.flatnonzero(np.diff(v) != 0) + 1, v.size])
            if v.size >= RUN_BLOCK * lengths.size:
                run_blocks += 1
                short_runs += int(np.sum(lengths < LONG_RUN))
            else:
                gathered_blocks += 1
    return run_blocks, short_runs, gathered_blocks


@pytest.mark.parametrize("layout", ["scattered", "runs"])
@pytest.mark.parametrize("smooth", [True, False], ids=["vertex normals", "flat facets"])
def test_the_gather_matches_its_definitions(smooth, layout):
    from raycore.geometry.camera import camera_basis
    from raycore.config import GATHER_BLOCK
    from raycore.shading.surface import visible_surface
    from raycore.grid.trace import row_major_offsets
    rng = np.random.default_rng(11)
    verts, faces, normals = _mesh(rng)
    n_t = len(faces)
    w, h = GATHER_BLOCK * 2 + 7, GATHER_BLOCK + 9                  # part-empty edge blocks
    cam = camera_basis([0.0, 0.0, 9.0], [0, 0, 0], [0, 1, 0], 50.0, w, h)
    n = w * h
    if layout == "runs":
        prim = _runs(rng, w, h, n_t)
        prim[rng.random(n) < 0.05] = -1                              # misses, inside runs too
        run_blocks, short_runs, gathered_blocks = _block_paths(prim, w, h)
        assert run_blocks and short_runs and gathered_blocks         # every path of fill_block taken
    else:
        prim = rng.integers(0, n_t, n).astype(np.int32)
        prim[rng.random(n) < 0.3] = -1                               # misses
        prim[:40] = np.arange(40) % 3                                # the degenerate triangles hit
    b1 = rng.random(n).astype(np.float32)
    b2 = (rng.random(n) * (1 - b1)).astype(np.float32)
    cancel = np.flatnonzero(prim == 2)[::2]
    b1[cancel], b2[cancel] = 0.5, 0.0                                # where the normals of triangle 2 cancel
    t = (rng.random(n) * 10 + 1).astype(np.float32)
    uvs = rng.random((len(verts), 2)).astype(np.float32) * 3 - 1   # wraps around
    tex = rng.random((5, 7, 3)).astype(np.float32)
    materials = np.array([[0.9, 0.7, 0.5, 0.4, 24.0, 0, 0, 0],
                          [0.6, 0.5, 0.4, 0.2, 8.0, -1, 0, 0]], np.float32)
    tri_material = (np.arange(n_t) % 2).astype(np.int32)
    faces_in = faces if smooth else np.zeros((0, 3), np.int32)
    normals_in = normals if smooth else np.zeros((0, 3), np.float32)
    s = visible_surface(cam, (0.5, 0.5), t, prim, b1, b2, *row_major_offsets(w, h), verts[faces].reshape(-1, 9),
                        faces_in, normals_in, tri_material, materials, uvs, tex.reshape(-1),
                        np.array([[0, 7, 5]], np.int64))
    want = _oracle(cam, w, h, prim, b1, b2, t, verts, faces, normals, smooth, materials, tri_material, uvs, tex)
    order = np.argsort(s.pixel)                                       # the gather's rows go block by block
    assert np.array_equal(s.pixel[order], want["pixel"])
    assert np.array_equal(s.prim[order], prim[want["pixel"]])
    scale = np.abs(verts).max()
    for name, tol in (("point", 1e-6 * scale), ("lifted", 1e-6 * scale), ("view", 1e-6), ("geo_n", 1e-5),
                      ("smooth_n", 1e-5), ("albedo", 1e-5)):
        got = getattr(s, name)[:, order].T
        np.testing.assert_allclose(got, want[name], atol=tol, err_msg=name)
    np.testing.assert_allclose(s.depth[order], want["depth"], rtol=1e-6)
    np.testing.assert_allclose(s.mag[order], want["mag"], rtol=1e-6)
    ks, shin = materials[tri_material[s.prim]][:, 3], materials[tri_material[s.prim]][:, 4]
    assert np.array_equal(s.ks, ks) and np.array_equal(s.shininess, shin)
    # the degenerate triangles: no normal of their own (zero), and the
    # cancelling vertex normals fall back to the geometric normal
    first = np.isin(s.pixel, np.arange(40))
    assert np.all(s.geo_n[:, first & (s.prim < 2)] == 0)
