"""Area lights as sets of point emitters.

An area light is `samples` isotropic point emitters, each with 1/samples of
its intensity, spread evenly over a rectangle (corner + u edge_u + v edge_v)
or over the surface of a sphere (center, radius), the same for every pixel,
so that emitter k's shadow rays are one coherent set of light-space packets
(geometry/light_rays.py, as for a point light).

The points are centred on the light for every count (emitter_uv): pairs
mirrored through the centre (a point of the (0, 2)-sequence in one half,
its image in the other; on a sphere, antipodes), and the centre itself when
the count is odd, so that one sample is the point light at the centre and
no count shifts the shadow. The Halton sequence used before started at
(1/2, 1/3): one sample sat 1/6 of edge_v off the centre, and the centroid of
4 was (0.41, 0.39). The pairs come first, and every prefix of
them spreads over the whole light, so the first emitters serve as probes
of it (render.light_probes, frame.py).

Radiance: a surface point receives sum_k (I / N) color max(0, n.l_k) / d_k^2
times the visibility of emitter k. As the light shrinks, every emitter
moves to one point and the sum becomes that point light's exactly; as N
grows it converges to the integral over the light of the same isotropic
emission (tests/render/test_area_lights.py checks both).
"""
import numpy as np

from raycore.geometry.sampling import sample_offset


def emitter_uv(n: int) -> np.ndarray:
    """(n, 2) points of the unit square whose centroid is (1/2, 1/2): the
    pixel sampler's mirrored pairs (raycore.geometry.sampling.sample_offset 1..2p),
    then the centre if n is odd. For n = 1, the centre."""
    pairs = [sample_offset(i) for i in range(1, 2 * (n // 2) + 1)]
    return np.array(pairs + [(0.5, 0.5)] * (n % 2), np.float64).reshape(n, 2)


def emitter_positions(light) -> np.ndarray:
    """(samples, 3) positions of an area light's point emitters."""
    uv = emitter_uv(light.samples)
    if light.corner is not None:
        corner, eu, ev = (np.asarray(v, np.float64) for v in (light.corner, light.edge_u, light.edge_v))
        return corner + uv[:, :1] * eu + uv[:, 1:] * ev
    # on the sphere: each pair's first point uniform over the lower hemisphere
    # (z = 1 - 2u with u in [1/2, 1), azimuth 2 pi v), its partner the
    # antipode; an odd count's last emitter is the centre
    n_pairs = light.samples // 2
    u, v = uv[:2 * n_pairs:2, 0], uv[:2 * n_pairs:2, 1]
    z = 1.0 - 2.0 * u
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * v
    half = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    unit = np.zeros((light.samples, 3))
    unit[0:2 * n_pairs:2], unit[1:2 * n_pairs:2] = half, -half
    return np.asarray(light.center, np.float64) + light.radius * unit
