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


class _Refined:
    """The pixels being refined, each with a slot: running sums of their
    samples (the centre sample included), nearest depth and sample count."""

    def __init__(self, rgba, z, n_pix):
        self.rgba, self.z = rgba, z
        self.slot = np.full(n_pix, -1, np.int64)
        self.pixels = np.zeros(0, np.int64)
        self.sums = np.zeros((0, 4), np.float64)
        self.zmin = np.zeros(0, np.float32)
        self.count = np.zeros(0, np.int64)

    def add(self, pixels):
        """Slots for `pixels` (not yet refined), which start from their
        1-spp sample; returns the slots."""
        first = self.pixels.size
        self.pixels = np.concatenate([self.pixels, pixels])
        self.sums = np.concatenate([self.sums, self.rgba[pixels].astype(np.float64)])
        self.zmin = np.concatenate([self.zmin, self.z[pixels]])
        self.count = np.concatenate([self.count, np.ones(pixels.size, np.int64)])
        self.slot[pixels] = np.arange(first, self.pixels.size)
        return np.arange(first, self.pixels.size)


def _advance(px, slots, total, offsets, totals, trace_passes, bg, n_pix):
    """Take the pixels of `slots` (all with one sample count) to `total`
    samples; returns the sums at the round's half (see half_difference)
    and where that half lies."""
    done = int(px.count[slots[0]])
    pixels = px.pixels[slots]
    # the estimate compares two halves: in a nested round, the centre and the
    # first half of the pairs against the rest; in the last round, the
    # samples before it against the plain set
    half_at = done if total == totals[-1] else max((total - 1) // 2, done)
    half = px.sums[slots] if done == half_at else None
    value = np.empty((px.pixels.size, 4), np.float32)
    # the round's passes in groups of about one image's worth of samples:
    # traced and shaded together, their shadow rays are one denser set
    group = max(1, n_pix // pixels.size)
    i = done
    while i < total:
        end = min(i + group, total)
        if i < half_at < end:
            end = half_at                              # a group ends at the half
        for hit_pixel, rgb, depth in trace_passes(pixels, offsets[i:end]):
            add_pass(pixels, px.slot, hit_pixel, rgb, depth, bg, px.sums, px.zmin, value)
        if end == half_at:
            half = px.sums[slots]                      # a copy
        i = end
    px.count[slots] = total
    return half, half_at


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
    the estimate a pixel stopped at (1 spp: the neighbour contrast).

    A pixel's neighbour term is the contrast it has seen, weighted by the
    samples it had when it saw it, over the samples it has now. After every
    round the contrast is measured again on the refined means: where a
    pixel's neighbours now show more than it had seen (a faint blurred edge
    that the neighbour's later samples found, which all of this pixel's
    samples missed), the new contrast counts with the pixel's samples now,
    and a pixel that had stopped, or had not started, is refined again."""
    n_pix = width * height
    bg = np.asarray(background, np.float32)
    padded = with_border_ring(rgba, width, height, bg, trace_passes)
    inner = np.empty((height + 2) * (width + 2), np.float32)

    def contrast_now():
        neighbour_contrast(padded, width + 2, height + 2, inner)
        return np.ascontiguousarray(inner.reshape(height + 2, width + 2)[1:-1, 1:-1]).reshape(-1)
    estimate = contrast_now()
    # under motion blur or a thin lens the 1-spp image is one instant and the
    # lens centre: every pixel takes the first round, and its contrast, seen
    # on no real mean yet, counts as unseen
    blurred = times_lens is not None
    seen = np.zeros(n_pix, np.float32) if blurred else estimate.copy()
    weight = estimate.astype(np.float64)                  # seen contrast x samples then
    samples = np.ones(n_pix, np.int32)
    start = np.flatnonzero((estimate > max_error) | blurred).astype(np.int64)
    if cap <= 1 or start.size == 0:
        return samples, estimate
    offsets, totals = budget_offsets(cap)
    if blurred:
        offsets = [o + tuple(s) for o, s in zip(offsets, times_lens)]
    px = _Refined(rgba, z, n_pix)
    live = px.add(block_order(start, width))
    while live.size:
        # each group of live pixels with one sample count to its next round
        half_err = np.zeros(live.size)
        for done in np.unique(px.count[live]):
            group = np.flatnonzero(px.count[live] == done)
            total = totals[int(np.searchsorted(totals, done, side="right"))]
            half, half_at = _advance(px, live[group], total, offsets, totals, trace_passes, bg, n_pix)
            half_err[group] = half_difference(half, px.sums[live[group]], half_at, total - half_at)
        samples[px.pixels] = px.count
        # the contrast on the refined means, against what each pixel had seen
        padded.reshape(height + 2, width + 2, 4)[1 + px.pixels // width, 1 + px.pixels % width] = \
            px.sums / px.count[:, None]
        now = contrast_now()
        more = now > seen
        seen[more] = now[more]
        weight[more] = np.maximum(weight[more], now[more].astype(np.float64) * samples[more])
        estimate[px.pixels[live]] = half_err
        estimate = np.maximum(estimate, (weight / samples).astype(np.float32))
        # on: every pixel above the budget with samples left to take
        wanted = (estimate > max_error) & (samples < totals[-1])
        new = np.flatnonzero(wanted & (px.slot < 0))
        on = np.sort(px.slot[np.flatnonzero(wanted & (px.slot >= 0))])      # slots are in block order
        live = np.concatenate([on, px.add(block_order(new, width))]) if new.size else on
    rgba[px.pixels] = (px.sums / px.count[:, None]).astype(np.float32)
    z[px.pixels] = px.zmin
    return samples, estimate
