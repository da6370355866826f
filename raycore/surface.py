"""Visible surface samples: the hits of one pass of camera rays, compacted
and turned into what shading and shadow rays need, once per pass.

Shading and every light read the same structure-of-arrays rows, so each
hit's triangle, normals and material are gathered once, not once per light,
and the per-light loops run over contiguous rows that vectorize.

Arrays of n visible samples (pixels whose camera ray hit), in blocks of
GATHER_BLOCK x GATHER_BLOCK pixels (row-major over the blocks and within each):
  pixel (n,) i32        row-major pixel index
  prim (n,) i32         triangle hit
  point (3, n) f32      hit point from the barycentrics
  lifted (3, n) f32     the point lifted toward the smooth surface the vertex
                        normals describe (Hanika 2021), where shadow rays start
  geo_n (3, n) f32      unit geometric normal, turned to the viewer
  smooth_n (3, n) f32   unit interpolated vertex normal, turned to the viewer
  view (3, n) f32       unit camera-ray direction
  depth (n,) f32        distance along the view axis (SPEC Z)
  mag (n,) f32          max |coordinate| of the hit triangle's vertices and of
                        the lifted point: the scale of their float32 error
  albedo (3, n) f32     diffuse colour, texture applied
  ks, shininess (n,)    specular weight and exponent
"""
from typing import NamedTuple

import numba
import numpy as np

from ._jit import helper, kernel, vector_kernel
from .camera import primary_dir
from .thread_pool import on_threads
from .tile_queue import new_queue, next_tile, tile_corner, tile_count
from .triangle import surface_point
from .workspace import scratch

F0 = np.float32(0.0)
F1 = np.float32(1.0)
HALF = np.float32(0.5)
GATHER_BLOCK = 32        # the gather's pixel blocks: the largest camera packet


class Surface(NamedTuple):
    pixel: np.ndarray
    prim: np.ndarray
    point: np.ndarray
    lifted: np.ndarray
    geo_n: np.ndarray
    smooth_n: np.ndarray
    view: np.ndarray
    depth: np.ndarray
    mag: np.ndarray
    albedo: np.ndarray
    ks: np.ndarray
    shininess: np.ndarray


@helper
def store3(rows, i, x, y, z):
    """Column i of a (3, n) structure-of-arrays block."""
    rows[0, i] = x
    rows[1, i] = y
    rows[2, i] = z


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
    # fx, fy >= -1/2: floor is truncation of fx + 1, minus 1 (the same
    # integers; a textured gather 5 % faster than int(np.floor(fx)))
    x0 = int(fx + F1) - 1
    y0 = int(fy + F1) - 1
    ax = fx - np.float32(x0)
    ay = fy - np.float32(y0)
    # fx in [-1/2, w - 1/2]: x0 >= -1 and x0 + 1 <= w, one wrap each (the
    # same texels, weights and sums as a wrap per tap; toys' gather 5 % faster)
    xa = x0 + w if x0 < 0 else x0
    xb = x0 + 1 - w if x0 + 1 >= w else x0 + 1
    ya = y0 + h if y0 < 0 else y0
    yb = y0 + 1 - h if y0 + 1 >= h else y0 + 1
    ka = off + ya * w * 3
    kb = off + yb * w * 3
    r = g = b = F0
    for k, wgt in ((ka + xa * 3, (F1 - ax) * (F1 - ay)), (ka + xb * 3, ax * (F1 - ay)),
                   (kb + xa * 3, (F1 - ax) * ay), (kb + xb * 3, ax * ay)):
        ku = np.uint64(k)            # unsigned: no negative-index wraparound
        r += wgt * tex_data[ku]
        g += wgt * tex_data[ku + np.uint64(1)]
        b += wgt * tex_data[ku + np.uint64(2)]
    return r, g, b


@kernel
def count_hits(hit_prim, row_off, col_off, block, block_count, queue):
    """Visible samples per block of block x block pixels (block_count (n_blocks,)
    i64, blocks row-major), for the blocks this thread pulls from `queue`
    (visible_surface starts one per thread, thread_pool.on_threads)."""
    width = col_off.shape[0]
    height = row_off.shape[0]
    blocks_x, _ = tile_count(width, height, block)
    while True:
        b = next_tile(queue, block_count.shape[0])
        if b < 0:
            break
        x0, y0 = tile_corner(b, blocks_x, block)
        c = 0
        for y in range(y0, min(y0 + block, height)):
            base = row_off[y]
            for x in range(x0, min(x0 + block, width)):
                c += 1 if hit_prim[base + col_off[x]] >= 0 else 0
        block_count[b] = c


@vector_kernel
def fill_block(cam, jx, jy, hit_prim, hit_b1, hit_b2, hit_t, row_off, col_off, block, b, blocks_x,
               tri_verts, faces, normals, tri_material, materials, uvs, tex_data, tex_info, start, found,
               pixel, prim_out, point, lifted, geo_n, smooth_n, view, depth, mag, albedo, ks, shininess):
    """Fill the Surface rows of block b's visible samples (block x block
    pixels, row by row), from row `start` on; returns the row after the
    last. found: (3, block^2) i64 scratch. Its own compiled function,
    called once a block: fill_surface writes the whole pass's rows,
    shade_blocks.shade_image a block's rows into buffers that stay in
    cache. Normals are turned to the viewer's side; the lift and the smooth
    normal use the vertex normals turned the same way.

    In three loops: the block's hits found (their index and pixel x, y), then
    every row filled in a loop without branches, which LLVM vectorizes
    (AVX-512 gathers; vector_kernel tells it that the arrays do not
    overlap), then the textures applied to the textured rows."""
    width = col_off.shape[0]
    height = row_off.shape[0]
    n = 0
    x0, y0 = tile_corner(b, blocks_x, block)
    for y in range(y0, min(y0 + block, height)):
        base = row_off[y]
        for x in range(x0, min(x0 + block, width)):
            # unsigned indices: a signed one costs a negative-index
            # wraparound (a compare and a select) at every load and store
            k = np.uint64(base + col_off[x])
            if hit_prim[k] >= 0:
                found[0, np.uint64(n)] = k
                found[1, np.uint64(n)] = x
                found[2, np.uint64(n)] = y
                n += 1
    smooth = faces.shape[0] > 0      # vertex normals given: lift and smooth normal
    for j in range(n):
        k = np.uint64(found[0, j])
        x = found[1, j]
        y = found[2, j]
        iu = np.uint64(start + j)
        prim = hit_prim[k]
        pu = np.uint64(prim)
        pixel[iu] = y * width + x
        prim_out[iu] = prim
        b1 = hit_b1[k]
        b2 = hit_b2[k]
        b0 = F1 - b1 - b2
        dx, dy, dz = primary_dir(cam, x, y, jx, jy)
        view[0, iu] = dx
        view[1, iu] = dy
        view[2, iu] = dz
        depth[iu] = hit_t[k] * (dx * cam[16] + dy * cam[17] + dz * cam[18])
        # point and unit geometric normal, turned to the viewer; the largest
        # vertex coordinate scales the point's float32 error
        px, py, pz, gx, gy, gz = surface_point(tri_verts, pu, b1, b2)
        m = F0
        for c in range(9):
            m = max(m, abs(tri_verts[pu, c]))
        side = -F1 if gx * dx + gy * dy + gz * dz > F0 else F1
        gx, gy, gz = side * gx, side * gy, side * gz
        # lift toward the smooth surface: p' = p - sum_i b_i min(0, (p - v_i).n_i) n_i
        qx = qy = qz = F0
        sx = sy = sz = F0
        for c in range(3):
            if smooth:
                w = b0 if c == 0 else (b1 if c == 1 else b2)
                v = np.uint64(faces[pu, c])
                nx, ny, nz = side * normals[v, 0], side * normals[v, 1], side * normals[v, 2]
                d = ((px - tri_verts[pu, 3 * c]) * nx + (py - tri_verts[pu, 3 * c + 1]) * ny
                     + (pz - tri_verts[pu, 3 * c + 2]) * nz)
                lift = -w * min(d, F0)
                qx += lift * nx
                qy += lift * ny
                qz += lift * nz
                sx += w * nx
                sy += w * ny
                sz += w * nz
        sl = np.sqrt(sx * sx + sy * sy + sz * sz)
        inv = F1 / sl if sl > F0 else F0
        sx, sy, sz = (sx * inv, sy * inv, sz * inv) if sl > F0 else (gx, gy, gz)
        lx, ly, lz = px + qx, py + qy, pz + qz
        store3(point, iu, px, py, pz)
        store3(lifted, iu, lx, ly, lz)
        mag[iu] = max(m, max(abs(lx), max(abs(ly), abs(lz))))
        store3(geo_n, iu, gx, gy, gz)
        store3(smooth_n, iu, sx, sy, sz)
        # material (a texture is applied after, by the caller)
        mat = np.uint64(tri_material[pu])
        albedo[0, iu] = materials[mat, 0]
        albedo[1, iu] = materials[mat, 1]
        albedo[2, iu] = materials[mat, 2]
        ks[iu] = materials[mat, 3]
        shininess[iu] = materials[mat, 4]
    if uvs.shape[0] > 0 and faces.shape[0] > 0 and tex_info.shape[0] > 0:
        # the textured samples listed first, without a branch (into found's
        # row 1: the pixels' x are no longer needed), then looked up in a
        # loop over them alone: the gather took 5-12 % less time on toys and
        # hand than with a skip of untextured samples inside the lookup loop
        n_tex = 0
        for j in range(n):
            pu = np.uint64(prim_out[np.uint64(start + j)])
            textured = materials[np.uint64(tri_material[pu]), 5] >= F0
            found[1, np.uint64(n_tex)] = j
            n_tex += 1 if textured else 0
        for q in range(n_tex):
            j = found[1, q]
            iu = np.uint64(start + j)
            pu = np.uint64(prim_out[iu])
            tex = int(materials[np.uint64(tri_material[pu]), 5])
            k = np.uint64(found[0, j])
            b1 = hit_b1[k]
            b2 = hit_b2[k]
            b0 = F1 - b1 - b2
            i0, i1, i2 = np.uint64(faces[pu, 0]), np.uint64(faces[pu, 1]), np.uint64(faces[pu, 2])
            tu = b0 * uvs[i0, 0] + b1 * uvs[i1, 0] + b2 * uvs[i2, 0]
            tv = b0 * uvs[i0, 1] + b1 * uvs[i1, 1] + b2 * uvs[i2, 1]
            tr, tg, tb = sample_texture(tex_data, tex_info, tex, tu, tv)
            albedo[0, iu] *= tr
            albedo[1, iu] *= tg
            albedo[2, iu] *= tb
    return start + n


@kernel
def fill_surface(cam, jx, jy, hit_prim, hit_b1, hit_b2, row_off, col_off, block, block_start,
                 tri_verts, faces, normals, tri_material, materials, uvs, tex_data, tex_info,
                 pixel, prim_out, point, lifted, geo_n, smooth_n, view, depth, mag, albedo, ks, shininess,
                 hit_t, queue):
    """Fill the Surface rows of the visible samples, block by block of
    block x block pixels (block b's samples start at block_start[b]): the
    order the camera packets wrote their hits in, so that the hits are read
    a cache line at a time (rows of the whole image read 32 of a packet's
    values and jumped: 10.5 against 9.6 ms on hand at 1024^2). The blocks
    this thread pulls from `queue` (visible_surface starts one per thread,
    thread_pool.on_threads; the visible surface is rarely spread evenly
    over the image). As a numba parallel loop it compiled in ~1.8 s more."""
    blocks_x, n_blocks = tile_count(col_off.shape[0], row_off.shape[0], block)
    found = np.empty((3, block * block), np.int64)
    while True:
        b = next_tile(queue, n_blocks)
        if b < 0:
            break
        fill_block(cam, jx, jy, hit_prim, hit_b1, hit_b2, hit_t, row_off, col_off, block, b, blocks_x,
                   tri_verts, faces, normals, tri_material, materials, uvs, tex_data, tex_info,
                   block_start[b], found, pixel, prim_out, point, lifted, geo_n, smooth_n, view, depth, mag,
                   albedo, ks, shininess)


def visible_surface(cam, jitter, hit_t, hit_prim, hit_b1, hit_b2, row_off, col_off,
                    tri_verts, faces, normals, tri_material, materials, uvs, tex_data,
                    tex_info, workspace=None) -> Surface:
    """The Surface of one pass of camera rays (hits of pixel (x, y) at
    row_off[y] + col_off[x]); faces (n_t, 3) and vertex normals of every
    triangle, or (0, 3) arrays for flat facets (no lift, geometric normals).
    With a Workspace the arrays are reused buffers, valid until its next use."""
    height = row_off.shape[0]
    width = col_off.shape[0]
    _, n_blocks = tile_count(width, height, GATHER_BLOCK)
    block_count = np.empty(n_blocks, np.int64)
    threads = numba.get_num_threads()
    on_threads(count_hits, threads, hit_prim, row_off, col_off, GATHER_BLOCK, block_count, new_queue())
    block_start = np.zeros(n_blocks + 1, np.int64)
    np.cumsum(block_count, out=block_start[1:])
    n = int(block_start[-1])
    f32 = np.float32

    pixels = height * width                     # the most samples a pass can have

    def take(name, shape, dtype=f32):
        return scratch(workspace, "surface." + name, shape, dtype, pixels * (3 if len(shape) > 1 else 1))
    s = Surface(*(take(name, (n,) if name in ("pixel", "prim", "depth", "mag", "ks", "shininess")
                       else (3, n), np.int32 if name in ("pixel", "prim") else f32)
                  for name in Surface._fields))
    on_threads(fill_surface, threads, cam, f32(jitter[0]), f32(jitter[1]), hit_prim, hit_b1, hit_b2, row_off,
               col_off, GATHER_BLOCK, block_start, tri_verts, faces, normals, tri_material, materials, uvs,
               tex_data, tex_info, *s, hit_t, new_queue())
    return s
