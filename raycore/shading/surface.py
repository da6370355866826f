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

from raycore.jit.presets import helper, kernel, vector_kernel
from raycore.geometry.camera import primary_dir
from raycore.jit.thread_pool import on_threads
from raycore.jit.tile_queue import new_queue, next_tile, tile_corner, tile_count
from raycore.geometry.triangle import surface_point
from raycore.jit.workspace import scratch
from raycore.jit.floats import F0, F1
from raycore.config import GATHER_BLOCK, LONG_RUN, RUN_BLOCK

HALF = np.float32(0.5)


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
def bilinear(tex_data, off, w, h, u, v):
    """Bilinear lookup with wrap-around in the texture at tex_data[off:]
    (w x h texels, RGB rows); v = 0 is the bottom row. float32 coordinates
    (an int64 size would turn them float64) and a +-w wrap, since texel
    indices only leave [0, w) by one."""
    fx = (u - np.floor(u)) * np.float32(w) - HALF
    fy = (F1 - (v - np.floor(v))) * np.float32(h) - HALF
    # fx, fy >= -1/2: floor is truncation of fx + 1, minus 1 (the same
    # integers; a textured gather 5 % faster than int(np.floor(fx))); by
    # np.int64, which LLVM can vectorize (int() is a call, see fill_block)
    x0 = np.int64(fx + F1) - 1
    y0 = np.int64(fy + F1) - 1
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


@helper
def tri_corners(tri_verts, pu):
    """Triangle pu's three corners, nine floats."""
    return (tri_verts[pu, 0], tri_verts[pu, 1], tri_verts[pu, 2], tri_verts[pu, 3], tri_verts[pu, 4],
            tri_verts[pu, 5], tri_verts[pu, 6], tri_verts[pu, 7], tri_verts[pu, 8])


@helper
def run_loop_takes(found, r, runs, textured_scene, prim_out, tri_material, materials, start):
    """Whether fill_block's run loop fills run r (rows found[3, r] to
    found[3, r + 1] - 1): a textured run, or in a block of long runs
    (`runs`) one of LONG_RUN rows or more."""
    j0 = found[3, r]
    if runs and found[3, r + 1] - j0 >= LONG_RUN:
        return True
    return textured_scene and materials[np.uint64(tri_material[np.uint64(prim_out[np.uint64(start + j0)])]), 5] >= F0


@helper
def unit_or(sx, sy, sz, gx, gy, gz):
    """(sx, sy, sz) made unit length, or (gx, gy, gz) where it is zero: the
    smooth normal, for which the geometric one stands in."""
    sl = np.sqrt(sx * sx + sy * sy + sz * sz)
    inv = F1 / sl if sl > F0 else F0
    return (sx * inv, sy * inv, sz * inv) if sl > F0 else (gx, gy, gz)


@helper
def lift_corner(px, py, pz, side, w, cx, cy, cz, nx, ny, nz, qx, qy, qz, sx, sy, sz):
    """Corner (cx, cy, cz), of barycentric weight w and vertex normal
    (nx, ny, nz) turned by `side`: its term of the lift toward the smooth
    surface, p' = p - sum_i b_i min(0, (p - v_i).n_i) n_i, added to
    (qx, qy, qz), and of the smooth normal, added to (sx, sy, sz); both
    of fill_block's loops call it. Their rows' stores, which they share
    too, are written out in each: in a helper of their own, the loops ran
    scalar (demo 36 -> 77 cycles a sample)."""
    nx, ny, nz = side * nx, side * ny, side * nz
    d = (px - cx) * nx + (py - cy) * ny + (pz - cz) * nz
    lift = -w * min(d, F0)
    return qx + lift * nx, qy + lift * ny, qz + lift * nz, sx + w * nx, sy + w * ny, sz + w * nz


@vector_kernel
def fill_block(cam, jx, jy, hit_prim, hit_b1, hit_b2, hit_t, row_off, col_off, block, b, blocks_x,
               tri_verts, faces, normals, tri_material, materials, uvs, tex_data, tex_info, start, found,
               pixel, prim_out, point, lifted, geo_n, smooth_n, view, depth, mag, albedo, ks, shininess):
    """Fill the Surface rows of block b's visible samples (block x block
    pixels, row by row), from row `start` on; returns the row after the
    last. found: (4, block^2 + 1) i64 scratch. Its own compiled function,
    called once a block: fill_surface writes the whole pass's rows,
    sweep.shade_image a block's rows into buffers that stay in
    cache. Normals are turned to the viewer's side; the lift and the smooth
    normal use the vertex normals turned the same way.

    The block's hits are found first (index, pixel x and y, triangle, and
    where each run of samples on one triangle starts, in found[3]). A
    triangle covers ~50-120 of a block's pixels on the built-in scenes, in
    runs of ~6-29 along a row. A run loop fills a run with its triangle's
    corners, normals, material, texture and UVs read once, as scalars
    (vectorized; the same sums as the gathered loop, which floating-point
    contraction may round 1 ulp apart). It takes every textured run, and in
    a block whose runs average RUN_BLOCK samples or more, every run of at
    least LONG_RUN. The other runs go through a loop that gathers each
    sample's data (vectorized, AVX-512 gathers): gathers cost ~1-2 cycles
    an element on this machine kind, but on a short run the run loop's
    scalar remainder costs more (cycles a sample: docs/performance.md).
    found's rows are read at unsigned indices: at a signed one, LLVM
    gathers them instead of loading them. The two loops are written out
    here, not as helpers: inlined, they compiled ~1 s longer."""
    width = col_off.shape[0]
    height = row_off.shape[0]
    n = 0
    n_runs = 0
    last = np.int32(-1)
    x0, y0 = tile_corner(b, blocks_x, block)
    for y in range(y0, min(y0 + block, height)):
        base = row_off[np.uint64(y)]
        for x in range(x0, min(x0 + block, width)):
            # unsigned indices: a signed one costs a negative-index
            # wraparound (a compare and a select) at every load and store
            k = np.uint64(base + col_off[np.uint64(x)])
            prim = hit_prim[k]
            if prim >= 0:
                found[0, np.uint64(n)] = k
                found[1, np.uint64(n)] = x
                found[2, np.uint64(n)] = y
                prim_out[np.uint64(start + n)] = prim
                pixel[np.uint64(start + n)] = y * width + x
                # a run's start, kept if the triangle changes (without a branch)
                found[3, np.uint64(n_runs)] = n
                n_runs += 1 if prim != last else 0
                last = prim
                n += 1
    smooth = faces.shape[0] > 0      # vertex normals given: lift and smooth normal
    textured_scene = uvs.shape[0] > 0 and smooth and tex_info.shape[0] > 0
    found[3, np.uint64(n_runs)] = n
    runs = n >= RUN_BLOCK * n_runs   # else only textured runs take the run loop
    r = 0
    while r < n_runs:
        j0 = found[3, r]
        j1 = found[3, r + 1]
        if run_loop_takes(found, r, runs, textured_scene, prim_out, tri_material, materials, start):
            # rows j0..j1-1, all on one triangle
            pu = np.uint64(prim_out[np.uint64(start + j0)])
            v0x, v0y, v0z, v1x, v1y, v1z, v2x, v2y, v2z = tri_corners(tri_verts, pu)
            _, _, _, g0x, g0y, g0z = surface_point(tri_verts, pu, F0, F0)
            m = F0
            for c in range(9):
                m = max(m, abs(tri_verts[pu, c]))
            f0 = f1 = f2 = np.uint64(0)
            n0x = n0y = n0z = n1x = n1y = n1z = n2x = n2y = n2z = F0
            if smooth:
                f0, f1, f2 = np.uint64(faces[pu, 0]), np.uint64(faces[pu, 1]), np.uint64(faces[pu, 2])
                n0x, n0y, n0z = normals[f0, 0], normals[f0, 1], normals[f0, 2]
                n1x, n1y, n1z = normals[f1, 0], normals[f1, 1], normals[f1, 2]
                n2x, n2y, n2z = normals[f2, 0], normals[f2, 1], normals[f2, 2]
            mat = np.uint64(tri_material[pu])
            kr, kg, kb = materials[mat, 0], materials[mat, 1], materials[mat, 2]
            mks, msh = materials[mat, 3], materials[mat, 4]
            # np.int64, not int(): numba's int() is a call that LLVM inlines only
            # after its loop vectorizer has passed (the loop then stays scalar)
            tex = np.int64(materials[mat, 5])
            textured = textured_scene and tex >= 0
            toff = tw = th = np.int64(1)
            u0 = w0 = u1 = w1 = u2 = w2 = F0
            if textured:
                toff, tw, th = tex_info[tex, 0], tex_info[tex, 1], tex_info[tex, 2]
                u0, w0, u1, w1, u2, w2 = uvs[f0, 0], uvs[f0, 1], uvs[f1, 0], uvs[f1, 1], uvs[f2, 0], uvs[f2, 1]
            for j in range(j0, j1):
                # unsigned: at a signed j, LLVM gathers found's rows instead
                # of loading them (4-7 cycles a sample more)
                ju = np.uint64(j)
                k = np.uint64(found[0, ju])
                x = found[1, ju]
                y = found[2, ju]
                iu = np.uint64(start + j)
                b1 = hit_b1[k]
                b2 = hit_b2[k]
                b0 = F1 - b1 - b2
                dx, dy, dz = primary_dir(cam, x, y, jx, jy)
                view[0, iu] = dx
                view[1, iu] = dy
                view[2, iu] = dz
                depth[iu] = hit_t[k] * (dx * cam[16] + dy * cam[17] + dz * cam[18])
                px = b0 * v0x + b1 * v1x + b2 * v2x
                py = b0 * v0y + b1 * v1y + b2 * v2y
                pz = b0 * v0z + b1 * v1z + b2 * v2z
                side = -F1 if g0x * dx + g0y * dy + g0z * dz > F0 else F1
                gx, gy, gz = side * g0x, side * g0y, side * g0z
                qx = qy = qz = F0
                sx = sy = sz = F0
                # without vertex normals, not a branch (each branch in the loop is
                # a copy of it, compiled): zero normals lift by 0 and give a zero
                # smooth normal, for which the geometric one stands in
                qx, qy, qz, sx, sy, sz = lift_corner(px, py, pz, side, b0, v0x, v0y, v0z, n0x, n0y, n0z,
                                                     qx, qy, qz, sx, sy, sz)
                qx, qy, qz, sx, sy, sz = lift_corner(px, py, pz, side, b1, v1x, v1y, v1z, n1x, n1y, n1z,
                                                     qx, qy, qz, sx, sy, sz)
                qx, qy, qz, sx, sy, sz = lift_corner(px, py, pz, side, b2, v2x, v2y, v2z, n2x, n2y, n2z,
                                                     qx, qy, qz, sx, sy, sz)
                sx, sy, sz = unit_or(sx, sy, sz, gx, gy, gz)
                lx, ly, lz = px + qx, py + qy, pz + qz
                store3(point, iu, px, py, pz)
                store3(lifted, iu, lx, ly, lz)
                mag[iu] = max(m, max(abs(lx), max(abs(ly), abs(lz))))
                store3(geo_n, iu, gx, gy, gz)
                store3(smooth_n, iu, sx, sy, sz)
                tr = tg = tb = F1
                if textured:
                    tr, tg, tb = bilinear(tex_data, toff, tw, th, b0 * u0 + b1 * u1 + b2 * u2, b0 * w0 + b1 * w1 + b2 * w2)
                albedo[0, iu] = kr * tr
                albedo[1, iu] = kg * tg
                albedo[2, iu] = kb * tb
                ks[iu] = mks
                shininess[iu] = msh
            r += 1
            continue
        # untextured short runs, up to the next run for the run loop
        r1 = n_runs if not runs and not textured_scene else r + 1
        while r1 < n_runs and not run_loop_takes(found, r1, runs, textured_scene, prim_out, tri_material, materials,
                                                 start):
            r1 += 1
        s1 = found[3, r1]
        # rows j0..s1-1, each sample's triangle, normals and material gathered
        for j in range(j0, s1):
            ju = np.uint64(j)
            k = np.uint64(found[0, ju])
            x = found[1, ju]
            y = found[2, ju]
            iu = np.uint64(start + j)
            pu = np.uint64(prim_out[iu])
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
            # lift toward the smooth surface and the smooth normal, corner by corner
            qx = qy = qz = F0
            sx = sy = sz = F0
            for c in range(3):
                if smooth:
                    w = b0 if c == 0 else (b1 if c == 1 else b2)
                    v = np.uint64(faces[pu, c])
                    qx, qy, qz, sx, sy, sz = lift_corner(px, py, pz, side, w, tri_verts[pu, 3 * c],
                                                         tri_verts[pu, 3 * c + 1], tri_verts[pu, 3 * c + 2],
                                                         normals[v, 0], normals[v, 1], normals[v, 2],
                                                         qx, qy, qz, sx, sy, sz)
            sx, sy, sz = unit_or(sx, sy, sz, gx, gy, gz)
            lx, ly, lz = px + qx, py + qy, pz + qz
            store3(point, iu, px, py, pz)
            store3(lifted, iu, lx, ly, lz)
            mag[iu] = max(m, max(abs(lx), max(abs(ly), abs(lz))))
            store3(geo_n, iu, gx, gy, gz)
            store3(smooth_n, iu, sx, sy, sz)
            mat = np.uint64(tri_material[pu])
            albedo[0, iu] = materials[mat, 0]
            albedo[1, iu] = materials[mat, 1]
            albedo[2, iu] = materials[mat, 2]
            ks[iu] = materials[mat, 3]
            shininess[iu] = materials[mat, 4]
        r = r1
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
    found = np.empty((4, block * block + 1), np.int64)
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
