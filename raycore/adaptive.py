"""An error budget for the pixels (`render.max_error`): rays only where the
image has not converged.

Every pixel starts with its centre sample (the 1 spp image, exactly as
without a budget). A pixel's error at 1 spp is estimated from its
neighbours: half the largest difference (any of R, G, B, A) to one of its
8 neighbours bounds how far the pixel's footprint can vary around its
centre. Pixels above the budget E are refined in rounds (7, 15, 31, ...
samples up to the cap), each pass one new sample offset for the active
pixels only; the caller traces and shades a group of passes together
(trace_passes), their rays ordered so that a packet holds neighbours.
After a round a pixel's error is estimated from the means of two halves
of its samples (those before the round, those of it), |mean_a - mean_b| / 2,
largest over R, G, B and A (Dammertz et al. 2010). The sample variance
would not do: these are low-discrepancy samples, whose mean converges far
faster than sqrt(var / n) says (an edge pixel's variance is that of a coin).
The estimate is never less than the 1-spp contrast over n: n samples can
all miss a feature about 1/n of the pixel wide, and then they agree. A
pixel at or below E stops, one above goes on until it has the cap: a pixel
whose estimate is above E always ends with every sample it may have.

Sample offsets (sample_offset): the centre, then points of the
(0, 2)-sequence, each with its mirror image through the centre: the samples
of every round, with those before, are stratified like a Hammersley set
and symmetric about the centre (no shift of the image); rounds nest, so no
sample is wasted.
"""
import numpy as np
from numba import prange

from ._jit import kernel, parallel_arith_kernel
from .camera import primary_dir

# samples a refined pixel has after each round: the centre and 3, 7, 15, ... pairs
ROUND_TOTALS = (7, 15, 31, 63, 127, 255, 511, 1023)
BLOCK = 8                    # active pixels are ordered by BLOCK x BLOCK blocks: packets of neighbours


def sobol_point(i: int) -> tuple:
    """Point i of the (0, 2)-sequence (Sobol's first two dimensions) with a
    digital shift of 1/2 (point 0 is (1/2, 1/2)): every run of 2^k points
    starting at a multiple of 2^k is a (0, k, 2)-net, one point in each of
    the 2^k strips of the square, across or along, as Hammersley's."""
    x = y = 0
    v = 1 << 31
    for bit in range(32):
        if i >> bit & 1:
            x ^= 1 << (31 - bit)              # van der Corput: the bits reversed
            y ^= v
        v ^= v >> 1
    return ((x ^ (1 << 31)) / 2.0 ** 32, (y ^ (1 << 31)) / 2.0 ** 32)


def sample_offset(i: int) -> tuple:
    """Sub-pixel offset of a pixel's sample i: 0 the centre, then pairs of a
    point q and its mirror image 1 - q through the centre, q running over
    the even points of the sequence (sobol_point(2m), which lie in the
    pixel's right half, the centre being the first). A net alone sits on
    multiples of 1/n, so its mean lies half a stratum off the centre (an
    image shifted by 1/(2n) pixel); mirrored, every prefix that ends a pair
    is symmetric about the centre and integrates a linear ramp exactly. The
    first 2^k - 1 samples are two (0, k - 1, 2)-nets of the two halves."""
    if i == 0:
        return 0.5, 0.5
    x, y = sobol_point(2 * ((i + 1) // 2))
    return (x, y) if i % 2 else (1.0 - x, 1.0 - y)


@parallel_arith_kernel
def neighbour_contrast(rgba, width, height, out):
    """out[p] = half the largest |difference| in any channel between pixel p
    and one of its 8 neighbours: the 1-spp error estimate."""
    for y in prange(height):
        for x in range(width):
            p = y * width + x
            worst = np.float32(0.0)
            for dy in range(-1, 2):
                yy = y + dy
                if yy < 0 or yy >= height:
                    continue
                for dx in range(-1, 2):
                    xx = x + dx
                    if xx < 0 or xx >= width:
                        continue
                    q = yy * width + xx
                    for c in range(4):
                        worst = max(worst, abs(rgba[p, c] - rgba[q, c]))
            out[p] = np.float32(0.5) * worst


@kernel
def camera_rays_of(cam, pixels, width, jx, jy, dirs):
    """Unit directions of the camera rays through `pixels` at offset (jx, jy)."""
    for i in range(pixels.shape[0]):
        p = pixels[i]
        d = primary_dir(cam, p % width, p // width, jx, jy)
        dirs[i, 0], dirs[i, 1], dirs[i, 2] = d[0], d[1], d[2]


@kernel
def add_pass(pixels, slot, surf_pixel, rgb, depth, bg, sums, zmin, value):
    """One sample of each of `pixels` into its running sums (row slot[p]):
    the background (A = 0) where its ray missed, the shaded colour (A = 1)
    where it hit (surf_pixel, rgb, depth: the pass's visible samples)."""
    for i in range(pixels.shape[0]):
        r = slot[pixels[i]]
        value[r, 0], value[r, 1], value[r, 2], value[r, 3] = bg[0], bg[1], bg[2], np.float32(0.0)
    for k in range(surf_pixel.shape[0]):
        r = slot[surf_pixel[k]]
        value[r, 0], value[r, 1], value[r, 2], value[r, 3] = rgb[0, k], rgb[1, k], rgb[2, k], np.float32(1.0)
        zmin[r] = min(zmin[r], depth[k])
    for i in range(pixels.shape[0]):
        r = slot[pixels[i]]
        for c in range(4):
            sums[r, c] += np.float64(value[r, c])


def block_order(pixels, width):
    """`pixels` sorted so that each run of BLOCK^2 lies in few BLOCK x BLOCK
    blocks (blocks row-major, pixels row-major inside)."""
    x, y = pixels % width, pixels // width
    blocks_x = -(-width // BLOCK)
    key = ((y // BLOCK) * blocks_x + x // BLOCK) * BLOCK * BLOCK + (y % BLOCK) * BLOCK + x % BLOCK
    return pixels[np.argsort(key, kind="stable")]


def half_difference(first, sums, n_first, n_second):
    """Error estimate of a pixel's mean from the means of its two halves: a
    (the n_first samples summed in `first`, centre and pairs) and b (the
    n_second pairs after them), each symmetric about the centre:
    |mean_a - mean_b| / 2, largest over the channels."""
    a = first / n_first
    b = (sums - first) / n_second
    return (np.abs(a - b) / 2).max(axis=1)


def refine(rgba, z, width, height, background, max_error, cap, trace_passes):
    """Spend samples where the 1-spp image `rgba` (H*W, 4), `z` (H*W,) is
    above `max_error`, up to `cap` samples per pixel, and write the means
    back into rgba and the nearest depth into z; a miss counts as
    `background` with A = 0.

    trace_passes(pixels, offsets) traces, for the pixel indices `pixels` (in
    block order), one camera ray each at every sub-pixel offset of
    `offsets`, shades the samples and returns per offset (surface_pixel,
    rgb (3, k), depth (k,)) of those that hit.

    Returns (samples per pixel (H*W,) int32, error estimate (H*W,) f32):
    the estimate a pixel stopped at (1 spp: the neighbour contrast)."""
    n_pix = width * height
    samples = np.ones(n_pix, np.int32)
    estimate = np.empty(n_pix, np.float32)
    neighbour_contrast(rgba, width, height, estimate)
    contrast = estimate.copy()
    active = np.flatnonzero(estimate > max_error).astype(np.int64)
    if cap <= 1 or active.size == 0:
        return samples, estimate
    active = block_order(active, width)
    m = active.size
    # running sums of the refined pixels, their centre sample included
    sums = rgba[active].astype(np.float64)
    zmin = z[active].copy()
    slot = np.full(n_pix, -1, np.int64)
    slot[active] = np.arange(m)
    value = np.empty((m, 4), np.float32)
    bg = np.asarray(background, np.float32)
    done = 1
    live = np.arange(m)                                   # slots still above the budget
    for total in ROUND_TOTALS:
        total = min(total, cap)
        if total <= done or live.size == 0:
            break
        pixels = active[live]
        # the first half: the centre and the first half of the pairs, i.e. the
        # samples before this round (when the cap cuts a round short, those too)
        half_at = max((total - 1) // 2, done)
        half = sums[live] if done == half_at else None
        # the round's passes in groups of about one image's worth of samples:
        # traced and shaded together, their shadow rays are one denser set
        group = max(1, n_pix // pixels.size)
        i = done
        while i < total:
            end = min(i + group, total)
            if i < half_at < end:
                end = half_at                              # a group ends at the half
            ids = range(i, end)
            for hit_pixel, rgb, depth in trace_passes(pixels, [sample_offset(k) for k in ids]):
                add_pass(pixels, slot, hit_pixel, rgb, depth, bg, sums, zmin, value)
            if end == half_at:
                half = sums[live]                          # a copy
            i = end
        done = total
        samples[pixels] = done
        err = np.maximum(half_difference(half, sums[live], half_at, done - half_at),
                         contrast[pixels] / done)
        estimate[pixels] = err
        live = live[err > max_error]
    rgba[active] = (sums / samples[active][:, None]).astype(np.float32)
    z[active] = zmin
    return samples, estimate
