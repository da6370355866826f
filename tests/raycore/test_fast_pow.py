"""raycore/shading/fast_pow.py: the vectorizable c ** s of the specular highlight
against numpy in float64, on random and on adversarial input."""
import numba
import numpy as np

from raycore.shading.fast_pow import pow_unit


@numba.njit(cache=False)
def _pow_all(c, s, out):
    for k in range(c.shape[0]):
        out[k] = pow_unit(c[k], s[k])


def _fast(c, s):
    c = np.ascontiguousarray(c, np.float32)
    s = np.ascontiguousarray(s, np.float32)
    out = np.empty_like(c)
    _pow_all(c, s, out)
    return out


def test_pow_unit_matches_float64_on_random_input(rng):
    """c uniform in (0, 1], close to 1 (the highlight's peak) and spread over
    30 decades; s from 0 to 2000: within 1.1e-7 absolute (an ulp at 1), and
    1e-6 relative where the result is at least 1/16."""
    n = 300_000
    c = np.concatenate([1 - rng.random(n), 1 - rng.random(n) * 1e-3, 10.0 ** rng.uniform(-30, 0, n)])
    s = np.concatenate([rng.uniform(0, 2000, n), rng.uniform(0, 64, n), rng.uniform(0, 10, n)])
    c, s = c.astype(np.float32), s.astype(np.float32)
    got = _fast(c, s)
    want = np.power(c.astype(np.float64), s.astype(np.float64))
    assert np.abs(got - want).max() <= 1.1e-7
    big = want >= 1 / 16
    assert big.sum() > n / 2
    assert (np.abs(got - want)[big] / want[big]).max() <= 1e-6


def test_pow_unit_at_its_edges():
    """Exact powers of two and the split point sqrt(1/2) of the mantissa; s =
    0 gives 1; huge exponents and tiny or subnormal c give (almost) 0; a c
    of 0, below 0, NaN or inf still gives a finite value (the caller's
    weight of 0 must not turn into NaN)."""
    f32 = np.float32
    half = f32(np.sqrt(0.5))
    c = np.array([1, 0.5, 0.25, 2.0 ** -20, half, np.nextafter(half, f32(0)), np.nextafter(half, f32(1)),
                  0.9, 0.9, 1e-38, 1e-45], np.float32)
    s = np.array([7, 3, 0.5, 2, 2, 2, 2, 0, 1e4, 1, 2], np.float32)
    got = _fast(c, s)
    want = np.power(c.astype(np.float64), s.astype(np.float64))
    np.testing.assert_allclose(got[:9], want[:9], rtol=1e-6, atol=1e-30)
    assert got[7] == 1.0 and got[9] < 1e-29 and got[10] < 1e-29
    odd = _fast(np.array([0, -1, np.nan, np.inf, -np.inf], np.float32), np.full(5, 32, np.float32))
    assert np.all(np.isfinite(odd))
