"""When and from where on the lens each pass of a frame looks: the shutter
time and lens position paired with every sub-pixel offset (sampling.py).

A frame of `spp` passes is an accumulation buffer (Haeberli and Akeley
1990): each pass is one image at one time and one lens position, so its
camera rays keep one origin and stay frustum packets, and its structures
are those of that time. The passes' times, lens positions and pixel
offsets cover the three domains together, as the jittered patterns of
distributed ray tracing (Cook, Porter and Carpenter 1984) do:

- plain `--spp n`: each of time, lens x and lens y takes every one of its
  n strata exactly once, in an order of its own (N-rooks, Shirley 1991):
  a step in time (an edge passing a pixel) is then integrated with an
  error of at most 1/n, and the dimensions do not align with each other or
  with the pixel offsets;
- the error budget's nested samples (sampling.sample_offset): the shutter
  time from the radical inverse in base 3 and the lens from bases 5 and 7,
  each shifted by 1/2, so that sample 0 (the 1-spp image) sits at the
  shutter's middle and the lens centre, and every prefix is spread over
  both.

Lens points go to the unit disc by Shirley and Chiu's concentric map,
which keeps the strata's areas and shapes.
"""
import numpy as np

from .sampling import nested_before_cap

# the N-rooks orders come from this seed: frames are the same on every run and machine
ORDER_SEED = 20061984


def concentric_disc(a, b):
    """The point of the unit disc for (a, b) in the unit square (Shirley
    and Chiu 1997): squares map to rings, area preserved, (1/2, 1/2) to 0."""
    x, y = 2.0 * a - 1.0, 2.0 * b - 1.0
    if x == 0.0 and y == 0.0:
        return 0.0, 0.0
    if abs(x) > abs(y):
        r, phi = x, (np.pi / 4) * (y / x)
    else:
        r, phi = y, np.pi / 2 - (np.pi / 4) * (x / y)
    return r * np.cos(phi), r * np.sin(phi)


def radical_inverse(i: int, base: int) -> float:
    """i's digits in `base` mirrored about the point: 0, 1/b, 2/b, ..., 1/b^2, ..."""
    f, inv = 0.0, 1.0 / base
    while i:
        f += inv * (i % base)
        i //= base
        inv /= base
    return f


def plain_times_lens(n: int) -> list:
    """(time, lens_x, lens_y) of the n passes of plain `--spp n`: time in
    [0, 1] across the shutter, lens on the unit disc; one pass: the
    shutter's middle and the lens centre."""
    if n <= 1:
        return [(0.5, 0.0, 0.0)]
    rng = np.random.default_rng(ORDER_SEED + n)
    strata = [(rng.permutation(n) + 0.5) / n for _ in range(3)]
    return [(float(t), *concentric_disc(float(a), float(b))) for t, a, b in zip(*strata)]


def nested_time_lens(i: int) -> tuple:
    """(time, lens_x, lens_y) of the error budget's nested sample i."""
    def shifted(base):
        return (radical_inverse(i, base) + 0.5) % 1.0
    return (shifted(3), *concentric_disc(shifted(5), shifted(7)))


def budget_times_lens(cap: int) -> list:
    """(time, lens_x, lens_y) of each of sampling.budget_offsets(cap): the
    nested samples', then plain `--spp cap`'s."""
    return [nested_time_lens(i) for i in range(nested_before_cap(cap))] + plain_times_lens(cap)
