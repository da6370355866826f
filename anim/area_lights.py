"""Area lights as sets of point emitters.

An area light is `samples` isotropic point emitters, each with 1/samples of
its intensity, spread evenly over a rectangle (corner + u edge_u + v edge_v)
or over the surface of a sphere (center, radius). The points are the Halton
sequence in bases 2 and 3, the same for every pixel, so that emitter k's
shadow rays are one coherent set of light-space packets (shadow_rays.py,
as for a point light). Halton rather than Hammersley: every prefix of it is
spread over the whole light too, so the first emitters serve as probes of
it (render.light_probes, frame.py).

Radiance: a surface point receives sum_k (I / N) color max(0, n.l_k) / d_k^2
times the visibility of emitter k. As the light shrinks, every emitter
moves to one point and the sum becomes that point light's exactly; as N
grows it converges to the integral over the light of the same isotropic
emission (tests/test_area_lights.py checks both).
"""
import numpy as np


def radical_inverse(i: int, base: int) -> float:
    """i's digits in `base` mirrored about the radix point."""
    f, inv = 0.0, 1.0 / base
    while i:
        f += inv * (i % base)
        i //= base
        inv /= base
    return f


def halton(n: int) -> np.ndarray:
    """(n, 2) points in (0, 1)^2: the Halton sequence in bases 2 and 3,
    from its second point (the first is the corner (0, 0))."""
    return np.array([(radical_inverse(i, 2), radical_inverse(i, 3)) for i in range(1, n + 1)]).reshape(n, 2)


def emitter_positions(light) -> np.ndarray:
    """(samples, 3) positions of an area light's point emitters."""
    uv = halton(light.samples)
    if light.corner is not None:
        corner, eu, ev = (np.asarray(v, np.float64) for v in (light.corner, light.edge_u, light.edge_v))
        return corner + uv[:, :1] * eu + uv[:, 1:] * ev
    z = 1.0 - 2.0 * uv[:, 0]                       # uniform on the sphere: z uniform, azimuth uniform
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * uv[:, 1]
    unit = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return np.asarray(light.center, np.float64) + light.radius * unit
