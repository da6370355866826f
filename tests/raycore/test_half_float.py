"""The parallel float32 -> half kernel against numpy, bit for bit."""
import numpy as np

from raycore.images.half_float import to_half


def _check(values):
    values = np.asarray(values, np.float32)
    with np.errstate(all="ignore"):
        ref = values.astype(np.float16)
    got = to_half(values)
    nan = np.isnan(values)
    assert np.isnan(got[nan]).all()
    bad = (ref.view(np.uint16) != got.view(np.uint16)) & ~nan
    assert not bad.any(), [hex(b) for b in values[bad].view(np.uint32)[:5]]


def test_random_bit_patterns():
    bits = np.random.default_rng(7).integers(0, 2 ** 32, size=2_000_000, dtype=np.uint64)
    _check(bits.astype(np.uint32).view(np.float32))


def test_every_half_value_and_its_rounding_neighbours():
    """Each half value, the float32 values next to it, and the exact ties
    halfway to the next half (ties go to the even mantissa)."""
    exact = np.arange(2 ** 16, dtype=np.uint32).astype(np.uint16).view(np.float16).astype(np.float32)
    bits = exact.view(np.uint32).astype(np.int64)
    around = [bits + d for d in (-2, -1, 0, 1, 2)]
    ties = [bits + (1 << 12) + d for d in (-1, 0, 1)] + [bits + (1 << 13)]
    _check((np.concatenate(around + ties) % 2 ** 32).astype(np.uint32).view(np.float32))


def test_named_edges():
    """Overflow threshold 65520, smallest subnormal and its tie, infinities, NaN, -0."""
    _check([65504.0, 65519.99, 65520.0, 1e6, np.inf, -np.inf, np.nan, -0.0, 0.0,
            2.0 ** -24, 2.0 ** -25, 2.0 ** -25 * 1.0000001, 2.0 ** -14, 2.0 ** -14 * 0.99999, 1e-30])


def test_shape_is_kept():
    x = np.arange(24, dtype=np.float32).reshape(2, 3, 4)
    assert to_half(x).shape == (2, 3, 4)
    assert np.array_equal(to_half(x), x.astype(np.float16))
