"""An error budget for the pixels (`render.max_error`): rays only where the
image has not converged.

Every pixel starts with its centre sample (the 1 spp image, exactly as
without a budget). A pixel's error at 1 spp is estimated from its
neighbours: half the largest difference (any of R, G, B, A) to one of its
8 neighbours bounds how far the pixel's footprint can vary around its
centre (a ring of samples one pixel outside the frame gives the border
pixels all 8). Pixels above the budget E are refined in rounds
(sampling.budget_offsets: nested rounds of 7, 15, 31, ... samples while a
round stays within a quarter of the cap, then the whole plain `--spp cap`
Hammersley set as the last round), each pass one new sample offset for the
active pixels only; the caller traces and shades a group of passes together
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

The nested samples (sampling.sample_offset): the centre, then points of
the (0, 2)-sequence, each with its mirror image through the centre: the
samples of every round, with those before, are stratified and symmetric
about the centre (no shift of the image); rounds nest, so no sample is
wasted. A pixel that reaches the cap therefore holds the plain `--spp cap`
pattern plus at most cap / 4 earlier samples: it is never worse than the
uniform image at the cap (tests/render/test_error_budget.py).

What is guaranteed is the estimate, not the true error: every pixel ends
with its estimate at or below E, or with every sample it may have. A
feature that no sample of a pixel or of its neighbours touches (a sliver
thinner than the samples' spacing) is invisible to the estimate.
"""
import numpy as np
from numba import prange

from raycore.jit.presets import kernel, parallel_arith_kernel
from raycore.geometry.camera import primary_dir
from raycore.geometry.sampling import budget_offsets

BLOCK = 8                    # active pixels are ordered by BLOCK x BLOCK blocks: packets of neighbours


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


def with_border_ring(rgba, width, height, bg, trace_passes):
    """The 1-spp image (H*W, 4) with a ring of samples one pixel outside it,
    ((H+2)*(W+2), 4): a border pixel's contrast then sees what lies just
    beyond the frame. Without it, an object entering through the bottom
    edge, below the last row's centres, left the corner pixel of hand at
    64^2 with error 0.17 under every budget: its neighbours all
    agreed. The ring costs 2 (W + H) + 4 camera rays, in three calls: the
    top row's pixels reach both horizontal sides (offsets y = -1/2 and
    H + 1/2), the left column's both vertical sides, pixel 0 the corners."""
    padded = np.empty((height + 2, width + 2, 4), np.float32)
    padded[1:-1, 1:-1] = rgba.reshape(height, width, 4)
    top, left = np.arange(width, dtype=np.int64), np.arange(height, dtype=np.int64) * width
    corner = np.zeros(1, np.int64)
    calls = ((top, [(0.5, -0.5), (0.5, height + 0.5)], [(0, slice(1, -1)), (-1, slice(1, -1))]),
             (left, [(-0.5, 0.5), (width + 0.5, 0.5)], [(slice(1, -1), 0), (slice(1, -1), -1)]),
             (corner, [(-0.5, -0.5), (width + 0.5, -0.5), (-0.5, height + 0.5), (width + 0.5, height + 0.5)],
              [(0, 0), (0, -1), (-1, 0), (-1, -1)]))
    for pixels, offsets, places in calls:
        for (hit_pixel, rgb, _), place in zip(trace_passes(pixels, offsets, aov=False), places):
            side = np.empty((pixels.size, 4), np.float32)
            side[:, :3], side[:, 3] = bg, 0.0
            rows = np.searchsorted(pixels, hit_pixel)
            side[rows, :3], side[rows, 3] = rgb.T, 1.0
            padded[place] = side if pixels.size > 1 else side[0]
    return padded.reshape(-1, 4)


def refine(rgba, z, width, height, background, max_error, cap, trace_passes, times_lens=None):
    """Spend samples where the 1-spp image `rgba` (H*W, 4), `z` (H*W,) is
    above `max_error`, up to the plain `cap`-sample set per pixel (plus the
    nested samples before it, sampling.budget_offsets), and write the means
    back into rgba and the nearest depth into z; a miss counts as
    `background` with A = 0.

    trace_passes(pixels, offsets, aov=True) traces, for the pixel indices
    `pixels` (in block order), one camera ray each at every sub-pixel offset
    of `offsets`, shades the samples and returns per offset (surface_pixel,
    rgb (3, k), depth (k,)) of those that hit; aov=False: samples that are
    not the pixel's (the border ring, offsets outside [0, 1]), kept out of
    the AOVs. times_lens: (time, lens_x, lens_y) of each budget offset
    (shutter_lens.budget_times_lens) under motion blur or a thin lens; the
    offsets handed to trace_passes are then (jx, jy, time, lens_x, lens_y),
    and every pixel takes the first nested round, whatever its contrast.

    Returns (samples per pixel (H*W,) int32, error estimate (H*W,) f32):
    the estimate a pixel stopped at (1 spp: the neighbour contrast)."""
    n_pix = width * height
    samples = np.ones(n_pix, np.int32)
    bg = np.asarray(background, np.float32)
    padded = with_border_ring(rgba, width, height, bg, trace_passes)
    contrast = np.empty((height + 2) * (width + 2), np.float32)
    neighbour_contrast(padded, width + 2, height + 2, contrast)
    estimate = np.ascontiguousarray(contrast.reshape(height + 2, width + 2)[1:-1, 1:-1]).reshape(-1)
    contrast = estimate.copy()
    # under motion blur or a thin lens one sample says nothing of what the
    # shutter or the lens spreads over a pixel: every pixel takes the first round
    active = np.flatnonzero((estimate > max_error) | (times_lens is not None)).astype(np.int64)
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
    offsets, totals = budget_offsets(cap)
    if times_lens is not None:
        offsets = [o + tuple(s) for o, s in zip(offsets, times_lens)]
    done = 1
    live = np.arange(m)                                   # slots still above the budget
    for total in totals:
        if live.size == 0:
            break
        pixels = active[live]
        # the estimate compares two halves: in a nested round, the centre and
        # the first half of the pairs against the rest; in the last round, the
        # samples before it against the plain set
        half_at = done if total == totals[-1] else max((total - 1) // 2, done)
        half = sums[live] if done == half_at else None
        # the round's passes in groups of about one image's worth of samples:
        # traced and shaded together, their shadow rays are one denser set
        group = max(1, n_pix // pixels.size)
        i = done
        while i < total:
            end = min(i + group, total)
            if i < half_at < end:
                end = half_at                              # a group ends at the half
            for hit_pixel, rgb, depth in trace_passes(pixels, offsets[i:end]):
                add_pass(pixels, slot, hit_pixel, rgb, depth, bg, sums, zmin, value)
            if end == half_at:
                half = sums[live]                          # a copy
            i = end
        done = total
        samples[pixels] = done
        if times_lens is not None and total == totals[0]:
            # every pixel now holds the first round's times and lens points:
            # the contrast of their means shows what the 1-spp image could
            # not (an edge that covers a pixel for the first 5 % of the
            # shutter, which all of its own samples missed), and it counts
            # as the contrast of `done` samples
            padded.reshape(height + 2, width + 2, 4)[1 + active // width, 1 + active % width] = sums / done
            after = np.empty((height + 2) * (width + 2), np.float32)
            neighbour_contrast(padded, width + 2, height + 2, after)
            contrast = np.maximum(contrast, after.reshape(height + 2, width + 2)[1:-1, 1:-1].reshape(-1) * done)
        err = np.maximum(half_difference(half, sums[live], half_at, done - half_at),
                         contrast[pixels] / done)
        estimate[pixels] = err
        live = live[err > max_error]
    rgba[active] = (sums / samples[active][:, None]).astype(np.float32)
    z[active] = zmin
    return samples, estimate
