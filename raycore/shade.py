"""Shading of the primary hits: Lambert + Blinn-Phong, point and directional
lights, optional textures, visibility from the shadow pass.

Arrays (all float32 unless noted):
  materials (n_mat, 8): kd r g b, ks, shininess, texture index (-1 none), -, -
  lights (n_light, 8): kind (0 point, 1 directional), x y z (position or the
      direction the light travels), r g b (colour * intensity), -
  tex_data (sum w*h*3,), tex_info (n_tex, 3) int64: offset, width, height
  uvs (n_v, 2): per-vertex texture coordinates, (0, 2) when no material has a texture
Point lights fall off with 1/d^2; directional lights do not.
"""
import numpy as np
from numba import prange

from ._jit import helper, parallel_arith_kernel
from .camera import primary_dir
from .triangle import surface_point

F0 = np.float32(0.0)
F1 = np.float32(1.0)
HALF = np.float32(0.5)
INF = np.float32(np.inf)


@helper
def sample_texture(tex_data, tex_info, tex, u, v):
    """Bilinear lookup with wrap-around; v = 0 is the bottom row. float32
    coordinates (an int64 size would turn them float64) and a +-w wrap, since
    texel indices only leave [0, w) by one."""
    off = tex_info[tex, 0]
    w = tex_info[tex, 1]
    h = tex_info[tex, 2]
    fx = (u - np.floor(u)) * np.float32(w) - HALF
    fy = (F1 - (v - np.floor(v))) * np.float32(h) - HALF
    x0 = int(np.floor(fx))
    y0 = int(np.floor(fy))
    ax = fx - np.float32(x0)
    ay = fy - np.float32(y0)
    r = g = b = F0
    for dy in range(2):
        yi = y0 + dy
        yi = yi + h if yi < 0 else (yi - h if yi >= h else yi)
        wy = ay if dy else F1 - ay
        for dx in range(2):
            xi = x0 + dx
            xi = xi + w if xi < 0 else (xi - w if xi >= w else xi)
            wgt = (ax if dx else F1 - ax) * wy
            k = off + (yi * w + xi) * 3
            r += wgt * tex_data[k]
            g += wgt * tex_data[k + 1]
            b += wgt * tex_data[k + 2]
    return r, g, b


@parallel_arith_kernel
def shade_pixels(cam, width, height, jx, jy, hit_t, hit_prim, hit_b1, hit_b2, row_off, col_off,
                 tri_verts, faces, normals, tri_material, materials, uvs,
                 tex_data, tex_info, lights, vis, use_vis, bg, ambient,
                 out_rgba, out_z, want_aov, aov_n, aov_p):
    """Colour (H*W, 4) and view-axis depth Z (H*W,) of every pixel.

    The hits of pixel (x, y) are at row_off[y] + col_off[x]: packet-major as
    the traversal wrote them, or row-major (row_off = y * W, col_off = x).

    vis (n_light, H*W) is read only when use_vis; aov_n / aov_p (H*W, 3)
    are written only when want_aov (otherwise they may be empty).
    """
    n_lights = lights.shape[0]
    has_uv = uvs.shape[0] > 0
    for y in prange(height):
        for x in range(width):
            p = y * width + x
            k = row_off[y] + col_off[x]
            prim = hit_prim[k]
            if prim < 0:
                out_rgba[p, 0] = bg[0]
                out_rgba[p, 1] = bg[1]
                out_rgba[p, 2] = bg[2]
                out_rgba[p, 3] = F0
                out_z[p] = INF
                if want_aov:
                    for c in range(3):
                        aov_n[p, c] = F0
                        aov_p[p, c] = F0
                continue
            dx, dy, dz = primary_dir(cam, x, y, jx, jy)
            out_z[p] = hit_t[k] * (dx * cam[3] + dy * cam[4] + dz * cam[5])
            b1 = hit_b1[k]
            b2 = hit_b2[k]
            b0 = F1 - b1 - b2
            px, py, pz, gx, gy, gz = surface_point(tri_verts, prim, b1, b2)
            # smooth normal, facing the viewer
            i0, i1, i2 = faces[prim, 0], faces[prim, 1], faces[prim, 2]
            nx = b0 * normals[i0, 0] + b1 * normals[i1, 0] + b2 * normals[i2, 0]
            ny = b0 * normals[i0, 1] + b1 * normals[i1, 1] + b2 * normals[i2, 1]
            nz = b0 * normals[i0, 2] + b1 * normals[i1, 2] + b2 * normals[i2, 2]
            length = np.sqrt(nx * nx + ny * ny + nz * nz)
            if length > F0:
                nx, ny, nz = nx / length, ny / length, nz / length
            else:
                nx, ny, nz = gx, gy, gz
            if nx * dx + ny * dy + nz * dz > F0:
                nx, ny, nz = -nx, -ny, -nz
            m = tri_material[prim]
            kr, kg, kb = materials[m, 0], materials[m, 1], materials[m, 2]
            ks = materials[m, 3]
            shininess = materials[m, 4]
            tex = int(materials[m, 5])
            if tex >= 0 and has_uv:
                tu = b0 * uvs[i0, 0] + b1 * uvs[i1, 0] + b2 * uvs[i2, 0]
                tv = b0 * uvs[i0, 1] + b1 * uvs[i1, 1] + b2 * uvs[i2, 1]
                tr, tg, tb = sample_texture(tex_data, tex_info, tex, tu, tv)
                kr *= tr
                kg *= tg
                kb *= tb
            cr = ambient * kr
            cg = ambient * kg
            cb = ambient * kb
            for li in range(n_lights):
                if use_vis and vis[li, p] == F0:
                    continue
                if lights[li, 0] == F0:
                    lx = lights[li, 1] - px
                    ly = lights[li, 2] - py
                    lz = lights[li, 3] - pz
                    d2 = lx * lx + ly * ly + lz * lz
                    atten = F1 / d2 if d2 > F0 else F0
                else:
                    lx = -lights[li, 1]
                    ly = -lights[li, 2]
                    lz = -lights[li, 3]
                    atten = F1
                ll = np.sqrt(lx * lx + ly * ly + lz * lz)
                if ll == F0:
                    continue
                lx, ly, lz = lx / ll, ly / ll, lz / ll
                ndl = nx * lx + ny * ly + nz * lz
                if ndl <= F0:
                    continue
                spec = F0
                if ks > F0:
                    hx, hy, hz = lx - dx, ly - dy, lz - dz
                    hl = np.sqrt(hx * hx + hy * hy + hz * hz)
                    ndh = (nx * hx + ny * hy + nz * hz) / hl if hl > F0 else F0
                    spec = ks * max(ndh, F0) ** shininess
                cr += lights[li, 4] * atten * (kr * ndl + spec)
                cg += lights[li, 5] * atten * (kg * ndl + spec)
                cb += lights[li, 6] * atten * (kb * ndl + spec)
            out_rgba[p, 0] = cr
            out_rgba[p, 1] = cg
            out_rgba[p, 2] = cb
            out_rgba[p, 3] = F1
            if want_aov:
                aov_n[p, 0] = nx
                aov_n[p, 1] = ny
                aov_n[p, 2] = nz
                aov_p[p, 0] = px
                aov_p[p, 1] = py
                aov_p[p, 2] = pz
