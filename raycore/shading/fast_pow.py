"""c ** s for the specular highlight, in a form LLVM vectorizes.

`c ** s` on float32 is a call to powf per sample, which no loop around it
can vectorize (numba's llvmlite wheels have no SVML): on hand at 1024^2 it
was 65 % of shading (shade_samples 4.8 ms, 1.7 without it). Here
c ** s = 2 ** (s log2 c), both halves from the float's bits and short
polynomials, branch-free:
  log2 c = e + log2 m, with c = m 2^e and m in [sqrt(1/2), sqrt(2)); log2 m
      = 2/ln 2 (t + t^3/3 + ... + t^9/9), t = (m - 1)/(m + 1), |t| <= 0.172
      (the first term left out is below 4e-10);
  2 ** y = 2^n e^(f ln 2), n = round(y), |f| <= 1/2: Taylor to the 7th
      power (what is left out is below 3e-9), 2^n from the exponent bits.
For c in (0, 1] and s in [0, 2000] the result is within 1.1e-7 of
float64's (an ulp at 1), and within 1e-6 of it relative where it is at
least 1/16 (tests/raycore/test_fast_pow.py against numpy; the rounding of
y = s log2 c to float32 is what is left, 4e-8 |y| relative, on values
of 2^y). c is taken as at least 1e-30 (c**s is then below any colour
for s >= 2) and y as at least -126 (2^-126: zero in any image), so every
lane stays finite whatever c holds: callers multiply by a weight of 0 where
the highlight is off instead of branching.
"""
import numpy as np
from numba.core import types
from numba.extending import intrinsic

from raycore.jit.presets import helper
from raycore.jit.floats import F1

SQRT_HALF_BITS = np.int32(0x3F3504F3)       # the bits of sqrt(1/2)
TWO_OVER_LN2 = np.float32(2.0 / np.log(2.0))
LN2 = np.float32(np.log(2.0))
C_MIN = np.float32(1e-30)
Y_MIN = np.float32(-126.0)


@intrinsic
def float_bits(typingctx, x):
    """The int32 whose bits are the float32 x's."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int32))
    return types.int32(types.float32), codegen


@intrinsic
def bits_float(typingctx, i):
    """The float32 whose bits are the int32 i's."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float32))
    return types.float32(types.int32), codegen


@helper
def log2_pos(c):
    """log2 of c > 0 (normal float32)."""
    b = float_bits(c)
    # split so that the mantissa m lies in [sqrt(1/2), sqrt(2)): e counts from
    # the exponent of sqrt(1/2)'s bits, m keeps the rest
    rel = b - SQRT_HALF_BITS
    e = rel >> np.int32(23)
    m = bits_float(b - (e << np.int32(23)))
    t = (m - F1) / (m + F1)
    t2 = t * t
    series = t * (F1 + t2 * (np.float32(1 / 3) + t2 * (np.float32(1 / 5) + t2 * (np.float32(1 / 7)
                                                                                + t2 * np.float32(1 / 9)))))
    return np.float32(e) + TWO_OVER_LN2 * series


@helper
def exp2_small(y):
    """2 ** y for y in [-126, 127]."""
    n = np.float32(np.floor(y + np.float32(0.5)))
    x = (y - n) * LN2                         # |x| <= ln 2 / 2
    p = F1 + x * (F1 + x * (np.float32(1 / 2) + x * (np.float32(1 / 6) + x * (np.float32(1 / 24) + x * (
        np.float32(1 / 120) + x * (np.float32(1 / 720) + x * np.float32(1 / 5040)))))))
    return p * bits_float((np.int32(n) + np.int32(127)) << np.int32(23))


@helper
def pow_unit(c, s):
    """c ** s for c in (0, 1] (any float c is made finite: at least 1e-30)
    and s >= 0."""
    c = c if c > C_MIN else C_MIN             # NaN too: no lane may poison a weight of 0
    y = s * log2_pos(c)
    y = y if y > Y_MIN else Y_MIN
    return exp2_small(min(y, np.float32(127.0)))
