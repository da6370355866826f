"""Texture lookup: texel centres exact, bilinear between them, wrap-around."""
import numpy as np
import pytest

from raycore.shading.surface import bilinear


def texture(w=4, h=3):
    texels = np.arange(w * h * 3, dtype=np.float32).reshape(h, w, 3)
    return texels, texels.reshape(-1), np.array([[0, w, h]], np.int64)


def lookup(u, v, w=4, h=3):
    _, data, _ = texture(w, h)
    return np.array(bilinear(data, 0, w, h, np.float32(u), np.float32(v)))


def test_texel_centres_are_exact_and_v0_is_the_bottom_row():
    img, _, _ = texture()
    for row in range(3):
        for col in range(4):
            u = (col + 0.5) / 4
            v = 1 - (row + 0.5) / 3
            np.testing.assert_allclose(lookup(u, v), img[row, col], atol=1e-4)


def test_bilinear_midpoint_and_wrap_around():
    img, _, _ = texture()
    mid = lookup(1.0 / 4, 1 - 0.5 / 3)                     # between columns 0 and 1 of row 0
    np.testing.assert_allclose(mid, (img[0, 0] + img[0, 1]) / 2, atol=1e-4)
    wrap = lookup(0.0, 1 - 0.5 / 3)                         # between column 3 and (wrapped) 0
    np.testing.assert_allclose(wrap, (img[0, 3] + img[0, 0]) / 2, atol=1e-4)
    np.testing.assert_allclose(lookup(1.3, 0.4), lookup(0.3, 0.4), atol=1e-4)
    np.testing.assert_allclose(lookup(-0.7, 0.4), lookup(0.3, 0.4), atol=1e-4)


def _bilinear(img, u, v):
    """Plain numpy bilinear lookup with wrap-around, v = 0 the bottom row."""
    h, w = img.shape[:2]
    fx = (u - np.floor(u)) * w - 0.5
    fy = (1 - (v - np.floor(v))) * h - 0.5
    x0, y0 = np.floor(fx).astype(int), np.floor(fy).astype(int)
    ax, ay = (fx - x0)[:, None], (fy - y0)[:, None]
    at = lambda yy, xx: img[yy % h, xx % w]
    return ((1 - ax) * (1 - ay) * at(y0, x0) + ax * (1 - ay) * at(y0, x0 + 1)
            + (1 - ax) * ay * at(y0 + 1, x0) + ax * ay * at(y0 + 1, x0 + 1))


def sphere_on_floor():
    """A textured, shiny sphere over a grey floor, a point and a directional
    light: (Geometry, Shading, (uvs, tex, materials, tri_material))."""
    from conftest import icosphere_mesh
    from raycore.frame import Geometry, Shading
    from raycore.geometry.mesh import vertex_face_csr

    v, f = icosphere_mesh(2, 1.0)
    floor = np.array([[-4, -1.2, -4], [4, -1.2, -4], [4, -1.2, 4], [-4, -1.2, 4]], np.float32)
    verts = np.concatenate([v, floor]).astype(np.float32)
    faces = np.concatenate([f, [[len(v), len(v) + 2, len(v) + 1], [len(v), len(v) + 3, len(v) + 2]]]).astype(np.int32)
    uvs = np.stack([np.arctan2(verts[:, 2], verts[:, 0]) / (2 * np.pi) + 0.5, verts[:, 1] * 0.4 + 0.5], 1).astype(np.float32)
    tex = np.random.default_rng(5).random((3, 4, 3)).astype(np.float32)
    n_t = len(faces)
    tri_material = np.zeros(n_t, np.int32)
    tri_material[-2:] = 1
    materials = np.array([[0.9, 0.7, 0.5, 0.4, 24.0, 0, 0, 0],        # textured, shiny
                          [0.6, 0.6, 0.6, 0.0, 8.0, -1, 0, 0]], np.float32)
    lights = np.array([[0, 2.5, 3.0, 2.0, 9.0, 8.0, 7.0, 0],
                       [1, -0.4, -1.0, -0.3, 0.5, 0.6, 0.7, 0]], np.float32)
    lights[1, 1:4] /= np.linalg.norm(lights[1, 1:4])
    shading = Shading(materials, tex.reshape(-1), np.array([[0, 4, 3]], np.int64), lights)
    vf = vertex_face_csr(faces, len(verts))
    geom = Geometry(verts, faces, tri_material, uvs, *vf)
    return geom, shading, (uvs, tex, materials, tri_material)


def test_shaded_frame_matches_a_numpy_oracle():
    """Every pixel of render_frame against Lambert + Blinn-Phong written out in
    numpy from the hits: smooth normals, 1/d^2 falloff, a texture, a point
    and a directional light, visibility from the (separately tested) shadow pass."""
    from conftest import tri_verts_of
    from raycore.geometry.camera import camera_basis
    from raycore.config import RenderConfig
    from raycore.frame import CameraPose, render_frame
    from raycore.geometry.mesh import vertex_normals
    from raycore.structures import FrameStructures
    from raycore.grid.trace import trace_camera
    from raycore.shading.visibility import trace_light

    geom, shading, (uvs, tex, materials, tri_material) = sphere_on_floor()
    verts, faces, lights, vf = geom.vertices, geom.faces, shading.lights, (geom.vf_start, geom.vf_faces)
    w, h = 80, 64
    pose = CameraPose((0.5, 1.5, 4.0), (0.0, -0.3, 0.0), (0, 1, 0), 45.0)
    cfg = RenderConfig(width=w, height=h, packet=16, ambient=0.05, background=(0.1, 0.2, 0.3))
    structures = FrameStructures(faces, len(verts), *vf, cfg.grid_density)
    result = render_frame(geom, shading, pose, cfg, structures=structures)

    tv = tri_verts_of(verts, faces)
    normals = np.empty((len(verts), 3), np.float32)
    vertex_normals(tv, *vf, normals)
    cam = camera_basis(pose.eye, pose.look_at, pose.up, pose.fov, w, h)
    grid, _ = structures.update(verts)               # the frame's own grid: grazing rays agree
    hits = trace_camera(grid, tv, cam, w, h, 16)
    vis = [trace_light(grid, tv, cam, w, h, hits, int(L[0]), L[1:4], smooth=(faces, normals))[0] for L in lights]
    from oracles import kernel_camera_rays
    _, d = kernel_camera_rays(cam, w, h, np.float32(0.5), np.float32(0.5))
    hit = hits.prim >= 0
    prim = hits.prim[hit]
    b = np.stack([1 - hits.b1[hit] - hits.b2[hit], hits.b1[hit], hits.b2[hit]], 1).astype(np.float64)
    fv = faces[prim]
    p = np.einsum("ik,ikj->ij", b, verts[fv].astype(np.float64))
    n = np.einsum("ik,ikj->ij", b, normals[fv].astype(np.float64))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    view = d[hit].astype(np.float64)
    n[np.einsum("ij,ij->i", n, view) > 0] *= -1
    mat = materials[tri_material[prim]].astype(np.float64)
    albedo = mat[:, :3].copy()
    textured = mat[:, 5] >= 0
    uv = np.einsum("ik,ikj->ij", b, uvs[fv].astype(np.float64))
    albedo[textured] *= _bilinear(tex.astype(np.float64), uv[textured, 0], uv[textured, 1])
    colour = 0.05 * albedo
    for li, L in enumerate(lights.astype(np.float64)):
        if L[0] == 0:
            to = L[1:4] - p
            atten = 1 / np.einsum("ij,ij->i", to, to)
        else:
            to = np.broadcast_to(-L[1:4], p.shape)
            atten = np.ones(len(p))
        l = to / np.linalg.norm(to, axis=1, keepdims=True)
        ndl = np.einsum("ij,ij->i", n, l)
        half = l - view
        half /= np.linalg.norm(half, axis=1, keepdims=True)
        spec = mat[:, 3] * np.maximum(np.einsum("ij,ij->i", n, half), 0) ** mat[:, 4]
        weight = np.where(ndl > 0, atten * vis[li][hit], 0.0)
        colour += L[4:7] * (weight * (albedo * ndl[:, None] + spec[:, None]).T).T
    expected = np.empty((w * h, 4))
    expected[:] = [0.1, 0.2, 0.3, 0.0]
    expected[hit, :3] = colour
    expected[hit, 3] = 1
    got = result.rgba.reshape(-1, 4)
    assert 0.3 < hit.mean() < 0.95 and textured.sum() > 500 and (mat[:, 3] > 0).sum() > 500
    # shading is exact; a shadow ray that grazes an edge may come out either
    # way between the frame's pass and the test's (1 pixel of 5120 seen)
    bad = ~np.all(np.isclose(got, expected, rtol=2e-4, atol=2e-5), axis=1)
    assert bad.sum() <= 0.001 * w * h, np.nonzero(bad)[0]
    np.testing.assert_allclose(got[~bad], expected[~bad], rtol=2e-4, atol=2e-5)
    z = np.where(hit, hits.t * (d @ cam[3:6]), np.inf)
    np.testing.assert_allclose(result.z.reshape(-1), z, rtol=1e-6)


def test_image_ring_keeps_a_frame_until_the_ring_comes_round():
    """Frames rendered with shared FrameBuffers reuse image memory in a ring:
    frame k's images stay as they were while frame k+1 renders, and a
    multi-sample frame after a one-sample frame starts from cleared images."""
    from conftest import icosphere_mesh
    from raycore.config import RenderConfig
    from raycore.frame import CameraPose, FrameBuffers, Geometry, Shading, render_frame
    from raycore.geometry.mesh import vertex_face_csr
    v, f = icosphere_mesh(2, 1.0)
    verts, faces = v.astype(np.float32), f.astype(np.int32)
    vf = vertex_face_csr(faces, len(verts))
    geom = Geometry(verts, faces, np.zeros(len(faces), np.int32), np.zeros((0, 2), np.float32), *vf)
    shading = Shading(np.array([[0.8, 0.8, 0.8, 0, 1, -1, 0, 0]], np.float32), np.zeros(1, np.float32),
                      np.zeros((0, 3), np.int64), np.array([[0, 2, 3, 4, 20, 20, 20, 0]], np.float32))
    cfg = RenderConfig(width=48, height=40, packet=8)
    poses = [CameraPose((0, 0, 4.0), (0, 0, 0), (0, 1, 0), 40.0),
             CameraPose((1.5, 0.5, 3.0), (0, 0, 0), (0, 1, 0), 55.0)]
    fresh = [render_frame(geom, shading, p, cfg) for p in poses]
    buffers = FrameBuffers(cfg.width, cfg.height, 1, cfg.packet, n_images=2)
    first = render_frame(geom, shading, poses[0], cfg, buffers)
    second = render_frame(geom, shading, poses[1], cfg, buffers)
    assert not np.shares_memory(first.rgba, second.rgba)
    for got, want in ((first, fresh[0]), (second, fresh[1])):
        np.testing.assert_array_equal(got.rgba, want.rgba)
        np.testing.assert_array_equal(got.z, want.z)
    third = render_frame(geom, shading, poses[1], cfg, buffers)      # the ring comes round
    assert np.shares_memory(third.rgba, first.rgba)
    cfg4 = RenderConfig(width=48, height=40, packet=8, spp=4)
    multi = render_frame(geom, shading, poses[0], cfg4, buffers)
    np.testing.assert_allclose(multi.rgba, render_frame(geom, shading, poses[0], cfg4).rgba, atol=1e-6)


@pytest.mark.parametrize("width, offset", [(96, 0), (88, 0), (96, 1), (84, 0), (77, 0)],
                         ids=["streamed", "streamed, edge blocks 24 wide", "image 4 bytes past alignment",
                              "width not a multiple of 8", "odd width"])
def test_the_block_write_paints_every_pixel_of_its_block(width, offset):
    """write_block's overwriting pass, every block of an image: samples where
    the block has them, the background elsewhere, pixels outside the block
    untouched, the same bits whether the rows went out by streaming stores
    (an image on 64-byte boundaries, widths a multiple of 8) or by plain
    stores (the image off a 32-byte boundary, other widths)."""
    from raycore.frame import aligned_empty
    from raycore.shading.shade import write_block
    rng = np.random.default_rng(5)
    height, block = 70, 32
    bg = np.array([0.1, 0.2, 0.3], np.float32)
    raw_rgba = aligned_empty(((width * height + 1) * 4,))
    raw_z = aligned_empty((width * height + 1,))
    rgba = raw_rgba[4 * offset:4 * offset + 4 * width * height].reshape(-1, 4)
    z = raw_z[offset:offset + width * height]
    assert (rgba.ctypes.data % 64 == 0) == (offset == 0)
    for y0 in range(0, height, block):
        for x0 in range(0, width, block):
            rgba[:] = 7.0
            z[:] = 7.0
            ys, xs = np.mgrid[y0:min(y0 + block, height), x0:min(x0 + block, width)]
            pix = (ys * width + xs).reshape(-1)
            hit = rng.random(pix.size) < (0.0 if (x0, y0) == (0, 0) else 0.6)     # one block without samples
            pixel = pix[hit].astype(np.int32)                                     # row-major, as the gather
            n = pixel.size
            rgb = rng.random((3, block * block)).astype(np.float32)
            depth = rng.random(block * block).astype(np.float32)
            write_block(pixel, rgb, depth, np.int64(n), np.int64(x0), np.int64(y0), np.int64(block),
                        np.int64(width), bg, np.float32(1.0), False, rgba, z)
            want_rgba = np.full_like(rgba, 7.0)
            want_z = np.full_like(z, 7.0)
            want_rgba[pix, :3], want_rgba[pix, 3], want_z[pix] = bg, 0.0, np.inf
            want_rgba[pixel, :3], want_rgba[pixel, 3], want_z[pixel] = rgb[:, :n].T, 1.0, depth[:n]
            np.testing.assert_array_equal(rgba, want_rgba)
            np.testing.assert_array_equal(z, want_z)


def test_the_vertex_face_table_is_a_stable_sort_of_the_corners(rng):
    """vertex_face_csr's counting sort against numpy's stable argsort of the
    corners (the oracle): each vertex's faces in increasing order, a face
    listed twice where it names a vertex twice, unused vertices empty."""
    from raycore.geometry.mesh import vertex_face_csr
    faces = rng.integers(0, 300, (2000, 3)).astype(np.int32)
    faces[::7, 1] = faces[::7, 0]                         # degenerate: a vertex named twice
    start, incident = vertex_face_csr(faces, 400)         # vertices 300..399 unused
    flat = faces.reshape(-1)
    order = np.argsort(flat, kind="stable")
    np.testing.assert_array_equal(incident, order // 3)
    np.testing.assert_array_equal(np.diff(start), np.bincount(flat, minlength=400))
    assert start[0] == 0 and start[-1] == flat.size
