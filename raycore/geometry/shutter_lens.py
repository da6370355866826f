"""When and from where on the lens each pass of a frame looks: the shutter
time and lens position paired with every sub-pixel offset (geometry/sampling.py).

A frame of `spp` passes is an accumulation buffer (Haeberli and Akeley
1990): each pass is one image at one time and one lens position, so its
camera rays keep one origin and stay frustum packets, and its structures
are those of that time. The passes' times, lens positions and pixel
offsets cover the domains together, as the patterns of distributed ray
tracing (Cook, Porter and Carpenter 1984) do:

- plain `--spp n`: pass i's pixel offset is Hammersley point i
  (sampling.sample_offsets: x = (i + 1/2) / n, y = radical inverse base 2);
  its time and lens position are the radical inverses of i in bases 3, 5
  and 7 (base 7's digits scrambled), each replaced by its rank among the n passes: every one of the n
  time strata (and lens-x, lens-y strata) is taken exactly once (a pixel
  centre that an edge covers for a share s of the shutter gets s within
  1/n), while every pair of dimensions keeps the Hammersley and Halton
  sets' even spread in the plane. (A Hammersley set of the lens's own, in
  a lattice order, correlated its y with the pixel's y at 0.93 for 256
  passes and shrank the depth of field's blur by 7 %.) A moving edge is a step in pixel position and time together: a
  set spread in both converges there as about n^-3/4 (stratified sampling
  of an edge, Mitchell 1996), against n^-1/2 for Latin-hypercube orders
  that are random between the dimensions (measured: slope -0.75 against
  -0.56, tests/render/test_motion_blur.py);
- the error budget's nested samples (sampling.sample_offset): the shutter
  time from the radical inverse in base 3 and the lens from bases 5 and 7,
  each shifted by 1/2, so that sample 0 (the 1-spp image) sits at the
  shutter's middle and the lens centre, and every prefix is spread over
  both.

Lens points go to the unit disc by Shirley and Chiu's concentric map,
which keeps the strata's areas and shapes.
"""
from functools import lru_cache

import numpy as np

from raycore.geometry.sampling import nested_before_cap, radical_inverse

# base 7's digits d taken as 4 d mod 7: the plain radical inverses in bases 5
# and 7 rise together for the first 5 passes (4 passes: all on one diagonal
# of the lens); scrambled, 5 passes fall on the lens like a lattice
LENS_Y_SCRAMBLE = 4


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


def ranks(values) -> np.ndarray:
    """Each value's place (0 ... n - 1) in the sorted values."""
    return np.argsort(np.argsort(values, kind="stable"), kind="stable")


@lru_cache(maxsize=None)
def plain_times_lens(n: int) -> tuple:
    """(time, lens_x, lens_y) of the n passes of plain `--spp n`: time in
    [0, 1] across the shutter, lens on the unit disc; one pass: the
    shutter's middle and the lens centre. Made once per n (3 ms at 1024
    passes, asked for every frame)."""
    if n <= 1:
        return ((0.5, 0.0, 0.0),)
    time, lens_a, lens_b = ((ranks([radical_inverse(i, base, scramble) for i in range(n)]) + 0.5) / n
                            for base, scramble in ((3, 1), (5, 1), (7, LENS_Y_SCRAMBLE)))
    return tuple((float(t), *concentric_disc(float(a), float(b))) for t, a, b in zip(time, lens_a, lens_b))


def nested_time_lens(i: int) -> tuple:
    """(time, lens_x, lens_y) of the error budget's nested sample i."""
    def shifted(base):
        return (radical_inverse(i, base) + 0.5) % 1.0
    return (shifted(3), *concentric_disc(shifted(5), shifted(7)))


@lru_cache(maxsize=None)
def budget_times_lens(cap: int) -> tuple:
    """(time, lens_x, lens_y) of each of sampling.budget_offsets(cap): the
    nested samples', then plain `--spp cap`'s."""
    return tuple(nested_time_lens(i) for i in range(nested_before_cap(cap))) + plain_times_lens(cap)
