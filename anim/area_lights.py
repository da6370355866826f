"""Area lights as sets of point emitters.

An area light is `samples` isotropic point emitters, each with 1/samples of
its intensity, spread evenly over a rectangle (corner + u edge_u + v edge_v)
or over the surface of a sphere (center, radius). The points are a
Hammersley set (stratified in one coordinate, radical inverse in the other),
the same for every pixel, so that emitter k's shadow rays are one coherent
set of light-space packets (shadow_packets.py, as for a point light).

Radiance: a surface point receives sum_k (I / N) color max(0, n.l_k) / d_k^2
times the visibility of emitter k. As the light shrinks, every emitter
moves to one point and the sum becomes that point light's exactly; as N
grows it converges to the integral over the light of the same isotropic
emission (tests/test_area_lights.py checks both).
"""
import numpy as np


def hammersley(n: int) -> np.ndarray:
    """(n, 2) points in [0, 1)^2: ((i + 0.5) / n, radical inverse of i)."""
    out = np.empty((n, 2))
    for i in range(n):
        bits, f, inv = i, 0.0, 0.5
        while bits:
            f += inv * (bits & 1)
            bits >>= 1
            inv *= 0.5
        out[i] = ((i + 0.5) / n, f)
    return out


def emitter_positions(light) -> np.ndarray:
    """(samples, 3) positions of an area light's point emitters."""
    uv = hammersley(light.samples)
    if light.corner is not None:
        corner, eu, ev = (np.asarray(v, np.float64) for v in (light.corner, light.edge_u, light.edge_v))
        return corner + uv[:, :1] * eu + uv[:, 1:] * ev
    z = 1.0 - 2.0 * uv[:, 0]                       # uniform on the sphere: z uniform, azimuth uniform
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * uv[:, 1]
    unit = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return np.asarray(light.center, np.float64) + light.radius * unit
