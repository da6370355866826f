"""Shadow rays from the smooth surface (vertex normals): against brute-force
occlusion of the same lifted points, and no stepped terminator on a coarse
sphere (every pixel the smooth normal turns to the light is lit)."""
import numpy as np

from conftest import icosphere_mesh, tri_verts_of
from oracles import brute_force_closest, kernel_camera_rays, shadow_origin
from raycore.geometry.camera import camera_basis
from raycore.grid.build import build_grid
from raycore.geometry.mesh import vertex_face_csr, vertex_normals
from raycore.grid.trace import trace_camera
from raycore.shading.visibility import trace_light
from raycore.geometry.triangle import surface_point


def _scene():
    v, f = icosphere_mesh(1, 1.0)                    # 80 facets: a coarse sphere
    floor_v = np.array([[-4, -1.5, -4], [4, -1.5, -4], [4, -1.5, 4], [-4, -1.5, 4]], np.float32)
    verts = np.concatenate([v, floor_v])
    faces = np.concatenate([f, [[len(v), len(v) + 2, len(v) + 1], [len(v), len(v) + 3, len(v) + 2]]]).astype(np.int32)
    tv = tri_verts_of(verts, faces)
    normals = np.empty((len(verts), 3), np.float32)
    vertex_normals(tv, *vertex_face_csr(faces, len(verts)), normals)
    return verts, faces, tv, normals


def test_smooth_shadow_origins_match_brute_force():
    verts, faces, tv, normals = _scene()
    grid = build_grid(tv)
    w = h = 64
    cam = camera_basis([0.3, 1.0, 4.0], [0, -0.3, 0], [0, 1, 0], 45, w, h)
    hits = trace_camera(grid, tv, cam, w, h, 16)
    _, dirs = kernel_camera_rays(cam, w, h, np.float32(0.5), np.float32(0.5))
    light = np.array([3.0, 2.0, 1.0], np.float32)
    vis, _ = trace_light(grid, tv, cam, w, h, hits, 0, light, 8, smooth=(faces, normals))
    checked = 0
    for p in np.nonzero(hits.prim >= 0)[0]:
        o, facing, to_light = shadow_origin(tv, hits.prim[p], hits.b1[p], hits.b2[p], dirs[p], 0, light,
                                            faces, normals)
        if not facing:
            assert vis[p] == 0
            continue
        dist = np.linalg.norm(to_light)
        ref = brute_force_closest(o[None].astype(np.float32), (to_light / dist)[None].astype(np.float32),
                                  np.zeros(1, np.float32), np.array([dist * (1 - 1e-6)], np.float32), tv)
        checked += 1
        if (ref[1][0] < 0) != (vis[p] == 1.0):      # only grazing rays may differ
            assert abs(ref[0][0] - dist) < 1e-3 * dist or ref[0][0] < 1e-3, p
    assert checked > 300


def test_no_stepped_terminator_on_a_coarse_sphere():
    verts, faces, tv, normals = _scene()
    grid = build_grid(tv)
    w = h = 96
    cam = camera_basis([0.0, 0.0, 4.0], [0, 0, 0], [0, 1, 0], 40, w, h)
    hits = trace_camera(grid, tv, cam, w, h, 16)
    light = np.array([4.0, 0.0, 0.5], np.float32)       # the terminator runs down the middle
    flat, _ = trace_light(grid, tv, cam, w, h, hits, 0, light, 8)
    smooth, _ = trace_light(grid, tv, cam, w, h, hits, 0, light, 8, smooth=(faces, normals))
    # a convex sphere cannot shadow itself where its smooth normal faces the
    # light: every such pixel must be lit; flat facets miss some (the steps)
    toward_light = []
    for p in np.nonzero(hits.prim >= 0)[0]:
        prim, b1, b2 = hits.prim[p], hits.b1[p], hits.b2[p]
        if prim >= 80:
            continue
        pt = np.array(surface_point(tv, prim, b1, b2)[:3])
        bary = (1 - b1 - b2, b1, b2)
        n = sum(bary[k] * normals[faces[prim, k]] for k in range(3))
        if n @ (light - pt) > 0.05 * np.linalg.norm(n) * np.linalg.norm(light - pt):
            toward_light.append(p)
    toward_light = np.array(toward_light)
    assert len(toward_light) > 1000
    assert np.all(smooth[toward_light] == 1.0)
    assert np.mean(flat[toward_light]) < 0.99              # the stepped terminator it fixes
