"""float32 -> IEEE half conversion on every core, for the EXR writer.

numpy's `astype(np.float16)` runs on one core at ~3 ns per value: 12 ms of
every 1024^2 RGBA frame. This kernel rounds the same way (to nearest, ties to
even; overflow to inf; half subnormals kept, float32 subnormals flushed as
they round to zero anyway) with integer operations only, so it vectorizes.
NaN stays a quiet NaN (its payload is dropped). Tested bit for bit against
numpy in tests/test_half_float.py.
"""
import numpy as np
from numba import prange

from ._jit import parallel_arith_kernel

_U = np.uint32
_F32_INF = _U(0x7F800000)
_F16_OVERFLOW = _U((127 + 16) << 23)          # 2^16: rounds to inf at or past 65520, see below
_MIN_NORMAL = _U(113 << 23)                   # 2^-14, the smallest normal half
_REBIAS = _U((127 - 15) << 23)               # float exponent bias minus half's
_CHUNK = 1 << 14


@parallel_arith_kernel
def half_bits(src_bits, out):
    """src_bits (n,) uint32 (a float32 array's .view(np.uint32)) -> out (n,) uint16."""
    n = src_bits.shape[0]
    for c in prange((n + _CHUNK - 1) // _CHUNK):
        for i in range(c * _CHUNK, min(n, (c + 1) * _CHUNK)):
            f = src_bits[i]
            sign = (f >> _U(16)) & _U(0x8000)
            f &= _U(0x7FFFFFFF)
            # normal: rebias the exponent, round the 13 dropped bits to nearest even
            # (a carry into the exponent is the correct result, up to inf)
            # (numba widens uint32 sums to 64 bits: subtract, never wrap by adding)
            normal = (f - _REBIAS + _U(0xFFF) + ((f >> _U(13)) & _U(1))) >> _U(13)
            normal = min(normal, _U(0x7C00))
            # subnormal: mantissa with its hidden bit, shifted right by 126 - e
            e = f >> _U(23)
            s = min(_U(126) - min(e, _U(126)), _U(31))
            m = (f & _U(0x7FFFFF)) | _U(0x800000)
            q = m >> s
            rem = m & ((_U(1) << s) - _U(1))
            half = (_U(1) << s) >> _U(1)
            q += _U(1) if (rem > half) | ((rem == half) & ((q & _U(1)) == _U(1))) else _U(0)
            sub = q if s <= _U(24) else _U(0)
            h = normal if f >= _MIN_NORMAL else sub
            h = _U(0x7C00) if f >= _F16_OVERFLOW else h
            h = _U(0x7E00) if f > _F32_INF else h
            out[i] = np.uint16(h | sign)


def to_half(values: np.ndarray, out: np.ndarray = None) -> np.ndarray:
    """float32 array (any shape, C-contiguous) -> float16 array of that shape."""
    values = np.ascontiguousarray(values, np.float32)
    if out is None:
        out = np.empty(values.shape, np.float16)
    half_bits(values.reshape(-1).view(np.uint32), out.reshape(-1).view(np.uint16))
    return out
