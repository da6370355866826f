"""Shading of visible surface samples (shading/surface.py): Lambert + Blinn-Phong,
point and directional lights, visibility from the shadow pass.

Arrays (all float32 unless noted):
  materials (n_mat, 8): kd r g b, ks, shininess, texture index (-1 none), -, -
  lights (n_light, 8): kind (0 point, 1 directional), x y z (position or the
      direction the light travels), r g b (colour * intensity), group (an
      area light's emitters share a number > 0, frame.light_groups; else 0)
Point lights fall off with 1/d^2; directional lights do not.

The loops run lights outside and samples inside, over contiguous
structure-of-arrays rows, so the per-sample work vectorizes; the image is
written by one scatter at the end.
"""
import numpy as np
from numba import prange

from raycore.jit.presets import arith_kernel, helper, kernel, parallel_arith_kernel
from raycore.shading.fast_pow import pow_unit
from raycore.jit.stream_store import store_fence, stream8
from raycore.jit.tile_queue import next_tile
from raycore.jit.floats import F0, F1, INF

CHUNK = 4096


@arith_kernel
def shade_rows(point, normal, view, albedo, ks, shininess, lights, vis, use_vis, ambient, i0, i1,
               out_rgb, spec_w, cos_h):
    """Colour of samples i0..i1-1 (see shade_samples); spec_w and cos_h:
    scratch of at least i1 - i0 floats. Its own compiled function, called
    once a chunk by shade_samples and once a block by the sweep (sweep.shade_blocks)."""
    m = i1 - i0
    # row slices, indexed by a counter from 0: LLVM can then drop the
    # negative-index checks and vectorize (an index i0 + k could not)
    px, py, pz = point[0, i0:i1], point[1, i0:i1], point[2, i0:i1]
    nx_, ny_, nz_ = normal[0, i0:i1], normal[1, i0:i1], normal[2, i0:i1]
    vx, vy, vz = view[0, i0:i1], view[1, i0:i1], view[2, i0:i1]
    ar, ag, ab = albedo[0, i0:i1], albedo[1, i0:i1], albedo[2, i0:i1]
    ks_c = ks[i0:i1]
    shin_c = shininess[i0:i1]
    r_out, g_out, b_out = out_rgb[0, i0:i1], out_rgb[1, i0:i1], out_rgb[2, i0:i1]
    for k in range(m):
        r_out[k] = ambient * ar[k]
        g_out[k] = ambient * ag[k]
        b_out[k] = ambient * ab[k]
    for li in range(lights.shape[0]):
        point_light = lights[li, 0] == F0
        lx, ly, lz = lights[li, 1], lights[li, 2], lights[li, 3]
        cr, cg, cb = lights[li, 4], lights[li, 5], lights[li, 6]
        # a one-sided emitter (columns 8-10: its emitting side's normal e):
        # a cosine lobe, -e . t, zero behind it; rows of 8 columns emit both ways
        ex = lights[li, 8] if lights.shape[1] > 10 else F0
        ey = lights[li, 9] if lights.shape[1] > 10 else F0
        ez = lights[li, 10] if lights.shape[1] > 10 else F0
        one_sided = (ex != F0) | (ey != F0) | (ez != F0)
        # without visibility, a row the loop only reads stands in (unread):
        # spec_w, which it writes, made LLVM's overlap check fail at run
        # time and the loop run scalar (hand's sweep without shadows, one
        # thread, 22.8 against 17.0 ms with a visibility row)
        vis_c = vis[li, i0:i1] if use_vis else ks_c
        n_spec = 0
        for k in range(m):
            if point_light:
                tx = lx - px[k]
                ty = ly - py[k]
                tz = lz - pz[k]
                d2 = tx * tx + ty * ty + tz * tz
                atten = F1 / d2 if d2 > F0 else F0
            else:
                tx, ty, tz = -lx, -ly, -lz
                d2 = tx * tx + ty * ty + tz * tz
                atten = F1
            inv = F1 / np.sqrt(d2) if d2 > F0 else F0
            tx, ty, tz = tx * inv, ty * inv, tz * inv
            nx, ny, nz = nx_[k], ny_[k], nz_[k]
            ndl = nx * tx + ny * ty + nz * tz
            w = atten * (vis_c[k] if use_vis else F1)
            w = w if ndl > F0 else F0
            if one_sided:
                w = w * max(-(ex * tx + ey * ty + ez * tz), F0)
            r_out[k] += cr * w * ar[k] * ndl
            g_out[k] += cg * w * ag[k] * ndl
            b_out[k] += cb * w * ab[k] * ndl
            # Blinn-Phong: half vector between the light and the viewer
            hx, hy, hz = tx - vx[k], ty - vy[k], tz - vz[k]
            hl2 = hx * hx + hy * hy + hz * hz
            ndh = (nx * hx + ny * hy + nz * hz) / np.sqrt(hl2) if hl2 > F0 else F0
            sw = w * ks_c[k] if ndh > F0 else F0
            spec_w[k] = sw
            cos_h[k] = ndh
            n_spec += 1 if sw > F0 else 0
        if n_spec == 0:
            continue
        for k in range(m):
            # branch-free: pow_unit is finite in every lane, and 0 where the weight is
            spec = spec_w[k] * pow_unit(cos_h[k], shin_c[k])
            r_out[k] += cr * spec
            g_out[k] += cg * spec
            b_out[k] += cb * spec


@kernel
def shade_samples(point, normal, view, albedo, ks, shininess, lights, vis, use_vis, ambient,
                  out_rgb, queue):
    """Colour (3, n) of every surface sample, for the chunks of CHUNK samples
    this thread pulls from `queue` (frame.py starts one per thread,
    thread_pool.on_threads; as a numba parallel loop it compiled ~1.5 s
    longer). vis (n_light, n) is read only when use_vis (1 lit, 0 shadowed).

    Per light, a branch-free loop over the samples (vectorized) adds the
    diffuse term and keeps each sample's specular weight and cos(n, h); a
    second loop raises cos(n, h) to the shininess (a scalar powf call in
    the first loop kept all of it from vectorizing: 8 ms -> 4 ms on the hand
    scene), with fast_pow.pow_unit, which vectorizes too (4.8 -> ~2 ms)."""
    n = point.shape[1]
    spec_w = np.empty(CHUNK, np.float32)
    cos_h = np.empty(CHUNK, np.float32)
    while True:
        c = next_tile(queue, (n + CHUNK - 1) // CHUNK)
        if c < 0:
            break
        i0 = c * CHUNK
        i1 = min(n, i0 + CHUNK)
        shade_rows(point, normal, view, albedo, ks, shininess, lights, vis, use_vis, ambient, i0, i1,
                   out_rgb, spec_w, cos_h)


@helper
def put_background(p, bg, weight, accumulate, out_rgba, out_z):
    """Pixel p as a miss: the background, A = 0, Z = +inf (accumulate: add
    weight * (background, 0) and leave Z)."""
    if accumulate:
        out_rgba[p, 0] += weight * bg[0]
        out_rgba[p, 1] += weight * bg[1]
        out_rgba[p, 2] += weight * bg[2]
    else:
        out_rgba[p, 0] = bg[0]
        out_rgba[p, 1] = bg[1]
        out_rgba[p, 2] = bg[2]
        out_rgba[p, 3] = F0
        out_z[p] = INF


@helper
def put_sample(p, rgb, i, depth, bg, weight, accumulate, out_rgba, out_z):
    """Sample i (colour rgb[:, i], Z depth[i]) into pixel p, which
    put_background has set: overwrite (A = 1), or accumulate: take back the
    background it was given, add weight * (colour, 1), keep the nearest Z."""
    if accumulate:
        out_rgba[p, 0] += weight * (rgb[0, i] - bg[0])
        out_rgba[p, 1] += weight * (rgb[1, i] - bg[1])
        out_rgba[p, 2] += weight * (rgb[2, i] - bg[2])
        out_rgba[p, 3] += weight
        out_z[p] = min(out_z[p], depth[i])
    else:
        out_rgba[p, 0] = rgb[0, i]
        out_rgba[p, 1] = rgb[1, i]
        out_rgba[p, 2] = rgb[2, i]
        out_rgba[p, 3] = F1
        out_z[p] = depth[i]


@parallel_arith_kernel
def write_pixels(pixel, rgb, depth, bg, weight, accumulate, out_rgba, out_z):
    """Scatter the samples into (H*W, 4) RGBA and (H*W,) Z. Overwrite: misses
    get the background with A = 0 and Z = +inf. accumulate (several samples
    per pixel; the caller zeroes RGBA and sets Z to +inf first): add weight *
    (colour, 1) of hits and weight * (background, 0) of misses, keep the
    nearest Z."""
    for p in prange(out_z.shape[0]):
        put_background(p, bg, weight, accumulate, out_rgba, out_z)
    n = pixel.shape[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        for i in range(c * CHUNK, min(n, (c + 1) * CHUNK)):
            put_sample(pixel[i], rgb, i, depth, bg, weight, accumulate, out_rgba, out_z)


@helper
def _put_sample4(dst, q, rgb, i):
    """dst[q:q + 4] = sample i's colour and alpha 1 (flat RGBA rows)."""
    dst[q] = rgb[0, i]
    dst[q + np.uint64(1)] = rgb[1, i]
    dst[q + np.uint64(2)] = rgb[2, i]
    dst[q + np.uint64(3)] = F1


@helper
def _streamed_rows(pixel, rgb, depth, n, x0, y0, m, block, width, height, bg, flat, out_z):
    """write_block's overwriting pass when every row of the block can go out
    by streaming stores (see there). The row buffers are made here, not
    passed in: LLVM then knows that they overlap nothing and vectorizes the
    loops over them (passed in, the block write took 12-14 cycles a sample
    instead of 7-9)."""
    b0, b1, b2 = bg[0], bg[1], bg[2]
    four = np.uint64(4)
    eight = np.uint64(8)
    row_rgba = np.empty(4 * block, np.float32)
    row_z = np.empty(block, np.float32)
    i = np.uint64(0)
    n_u = np.uint64(n)
    for y in range(y0, min(y0 + block, height)):
        p0 = np.uint64(y * width + x0)
        for k in range(m):
            q = k * four
            row_rgba[q] = b0
            row_rgba[q + np.uint64(1)] = b1
            row_rgba[q + np.uint64(2)] = b2
            row_rgba[q + np.uint64(3)] = F0
            row_z[k] = INF
        end = p0 + m
        while i < n_u and np.uint64(pixel[i]) < end:
            k = np.uint64(pixel[i]) - p0
            _put_sample4(row_rgba, k * four, rgb, i)
            row_z[k] = depth[i]
            i += np.uint64(1)
        for c in range(np.uint64(0), four * m, eight):
            stream8(flat, four * p0 + c, row_rgba, c)
        for c in range(np.uint64(0), m, eight):
            stream8(out_z, p0 + c, row_z, c)
    store_fence()


@arith_kernel
def write_block(pixel, rgb, depth, n, x0, y0, block, width, bg, weight, accumulate, out_rgba, out_z):
    """write_pixels for one block: the block x block pixels at (x0, y0) of
    an image `width` wide, and samples 0..n-1, the block's hits in
    row-major order (as surface.fill_block makes them); the same sums as
    write_pixels when accumulating.

    Overwriting, where every row of the block starts on a 32-byte boundary
    in the RGBA and the Z image and is a multiple of 8 pixels wide (the
    frame's images, frame.aligned_empty, at widths that are multiples of
    8), each row is composed in two small buffers (the background, then the
    row's samples over it) and written out by streaming stores
    (stream_store). Else the block's rows are filled with the background in
    place and the samples written over them (faster than one pass choosing
    per pixel; composed rows copied out by plain stores took twice as long).
    A plain store reads its line from memory first, and the 20 MB of a
    1024^2 frame's RGBA and Z are written once and not read again by the
    frame: streamed, they do not pass through the caches (about a third
    fewer cycles a sample: docs/performance.md). Accumulating, one pass over
    the pixels stays (each pixel's background weight is added once, as its
    samples are)."""
    height = out_z.shape[0] // width
    if not accumulate:
        flat = out_rgba.reshape(-1)
        m = np.uint64(min(x0 + block, width) - x0)
        # every row's RGBA and Z on 32-byte boundaries, whole lines of 8 floats
        if (m | np.uint64(x0) | np.uint64(width)) % np.uint64(8) == 0 and flat.ctypes.data % 32 == 0 \
                and out_z.ctypes.data % 32 == 0:
            _streamed_rows(pixel, rgb, depth, n, x0, y0, m, block, width, height, bg, flat, out_z)
            return
        b0, b1, b2 = bg[0], bg[1], bg[2]
        four = np.uint64(4)
        for y in range(y0, min(y0 + block, height)):
            p0 = np.uint64(y * width + x0)
            for k in range(m):
                q = (p0 + k) * four
                flat[q] = b0
                flat[q + np.uint64(1)] = b1
                flat[q + np.uint64(2)] = b2
                flat[q + np.uint64(3)] = F0
                out_z[p0 + k] = INF
        for i in range(n):
            iu = np.uint64(i)
            p = np.uint64(pixel[iu])
            _put_sample4(flat, p * four, rgb, iu)
            out_z[p] = depth[iu]
        return
    i = 0
    for y in range(y0, min(y0 + block, height)):
        for x in range(x0, min(x0 + block, width)):
            p = y * width + x
            if i < n and pixel[i] == p:
                put_background(p, bg, weight, accumulate, out_rgba, out_z)
                put_sample(p, rgb, i, depth, bg, weight, accumulate, out_rgba, out_z)
                i += 1
            else:
                put_background(p, bg, weight, accumulate, out_rgba, out_z)
