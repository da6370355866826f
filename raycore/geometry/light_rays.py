"""Shadow rays to one light, traced in packets that are coherent in light space.

Packets cut from camera tiles straddle silhouettes: one packet holds rays to
a hand and to the ground metres behind it, and its frustum sweeps through
everything between. For the grid's frustum walk, the kd-tree and scattered
samples (the error budget's), the rays are reordered first, so that a
packet's rays are neighbours as the light sees them (the BVH makes a camera
pass's rays itself, in the samples' order, from point_light_ray and
directional_light_ray: bvh/trace.trace_light_samples):
  * point light: every ray leaves the light (traced from the light to the
    surface point, same segment), so a packet shares its origin and takes the
    grid walk's shared-origin path (edge planes through the light, three dot
    products per ray). Rays are ordered by cube-map face and a Morton code of
    their direction on that face: a packet is a thin cone by construction.
  * directional light: the rays are parallel; they are ordered by a Morton
    code of their origin projected onto the plane normal to the light, so a
    packet is a thin box.
The order is a counting sort on (face, cell) keys, stable so that a cell
keeps the samples' order: a point light's cells divide each cube face,
a directional light's the range its points cover.

Ray origins (Hanika 2021 lift, then an offset along the geometric normal by
a bound on the float32 error, in the spirit of pbrt-v4's OffsetRayOrigin):
the lifted point's coordinates and the triangle's vertices carry an error of
a few ulps of their magnitude, and the ray's distance to the receiving plane
is computed from vertices, light and distance of that magnitude, so the
origin is pushed off by EPS_OFFSET_ULPS ulps of (vertex magnitude + light
magnitude + ray length). A ground plane of half-size 1e5 gets an offset of
~0.2, one of size 1 an offset of ~1e-6; the old fixed fraction of |p| was
both too small on large triangles near the origin (acne) and needlessly
large far from it.
"""
import numba
import numpy as np

from raycore.jit.presets import helper, kernel, vector_kernel
from raycore.config import EPS_OFFSET_ULPS, SHADOW_T_MIN_FRACTION

from raycore.jit.thread_pool import on_threads
from raycore.jit.tile_queue import new_queue, next_tile
from raycore.jit.workspace import scratch
from raycore.jit.floats import F0, F1, INF

ULP = np.float32(2.0 ** -24)
# rays per packet side: 32x32 rays = sixteen 8x8 sub-packets culled apart (8: 2.2x,
# 16: 1.3x the time on the hand scene)
SHADOW_PACKET = 32
# cells per face axis: 2^5. Within a cell the rays keep the gather's order
# (32x32-pixel blocks), which is itself coherent; finer cells only cut the
# blocks' runs apart (2^5 measured fastest of 2^0-2^7: docs/performance.md)
ORDER_BITS = 5
N_FACES = 6
# samples a thread takes at once in light_rays
RAY_CHUNK = 16384


@helper
def point_light_ray(lx, ly, lz, light_mag, lifted, geo_n, smooth_n, mag, offset_ulps, i):
    """Sample i's shadow ray to a point light at (lx, ly, lz) (light_mag: its
    largest |coordinate|), from the light to the sample's lifted point pushed
    off the surface: (unit direction, distance, t_max), t_max the distance,
    or -1 (inactive) where the smooth normal faces away from the light or
    the distance is 0."""
    qx, qy, qz = lifted[0, i], lifted[1, i], lifted[2, i]
    tx, ty, tz = lx - qx, ly - qy, lz - qz
    facing = smooth_n[0, i] * tx + smooth_n[1, i] * ty + smooth_n[2, i] * tz > F0
    dist0 = np.sqrt(tx * tx + ty * ty + tz * tz)
    off = offset_ulps * ULP * (mag[i] + light_mag + dist0)
    # from the light to the offset point
    dx = qx + geo_n[0, i] * off - lx
    dy = qy + geo_n[1, i] * off - ly
    dz = qz + geo_n[2, i] * off - lz
    dist = np.sqrt(dx * dx + dy * dy + dz * dz)
    inv = F1 / dist if dist > F0 else F0
    return dx * inv, dy * inv, dz * inv, dist, dist if (facing & (dist > F0)) else -F1


@helper
def directional_light_ray(lx, ly, lz, lifted, geo_n, smooth_n, mag, offset_ulps, i):
    """Sample i's shadow ray toward a directional light travelling along the
    unit (lx, ly, lz): (origin pushed off the surface, t_max), t_max inf,
    or -1 (inactive) where the smooth normal faces away from the light."""
    facing = smooth_n[0, i] * lx + smooth_n[1, i] * ly + smooth_n[2, i] * lz < F0
    off = offset_ulps * ULP * mag[i]
    return (lifted[0, i] + geo_n[0, i] * off, lifted[1, i] + geo_n[1, i] * off,
            lifted[2, i] + geo_n[2, i] * off, INF if facing else -F1)


@vector_kernel
def light_rays(kind, lx, ly, lz, lifted, geo_n, smooth_n, mag, offset_ulps,
               ray_o, ray_d, t_min, t_max, face, key_s, key_t, queue):
    """Shadow ray of every surface sample to one light (kind 0: point at
    (lx, ly, lz); 1: directional, travelling along the unit (lx, ly, lz)),
    for the chunks of RAY_CHUNK samples this thread pulls from `queue`
    (LightRays starts one per thread, thread_pool.on_threads). Inactive
    (t_max = -1) where the smooth normal faces away from the light. face /
    key_s / key_t: the light-space coordinates the packets are sorted by.
    One branch-free loop per kind, so that each vectorizes (one loop testing
    the kind per sample did not: 6.3 ms a light on hand at 1024^2); the
    arrays are distinct (vector_kernel: noalias)."""
    n = mag.shape[0]
    n_chunks = (n + RAY_CHUNK - 1) // RAY_CHUNK
    light_mag = max(abs(lx), abs(ly), abs(lz))
    # coordinates in the plane normal to a directional light (any fixed basis)
    if abs(lx) < np.float32(0.6):
        ux, uy, uz = F0, lz, -ly          # (1, 0, 0) x l
    else:
        ux, uy, uz = -lz, F0, lx          # (0, 1, 0) x l
    vx, vy, vz = ly * uz - lz * uy, lz * ux - lx * uz, lx * uy - ly * ux
    while True:
        c = next_tile(queue, n_chunks)
        if c < 0:
            break
        i0 = c * RAY_CHUNK
        i1 = min(n, i0 + RAY_CHUNK)
        if kind == 0:
            for k in range(i0, i1):
                i = np.uint64(k)          # unsigned: no negative-index wraparound, the loop vectorizes
                dx, dy, dz, dist, t_far = point_light_ray(lx, ly, lz, light_mag, lifted, geo_n, smooth_n, mag,
                                                          offset_ulps, i)
                ray_o[0, i] = lx
                ray_o[1, i] = ly
                ray_o[2, i] = lz
                ray_d[0, i] = dx
                ray_d[1, i] = dy
                ray_d[2, i] = dz
                t_min[i] = dist * SHADOW_T_MIN_FRACTION
                t_max[i] = t_far
                # cube-map face of the direction and its two coordinates on it
                ax, ay, az = abs(dx), abs(dy), abs(dz)
                x_major = (ax >= ay) & (ax >= az)
                y_major = (~x_major) & (ay >= az)
                f = np.int32(0 if dx > F0 else 1) if x_major else (
                    np.int32(2 if dy > F0 else 3) if y_major else np.int32(4 if dz > F0 else 5))
                s = dy if x_major else (dz if y_major else dx)
                t = dz if x_major else (dx if y_major else dy)
                big = ax if x_major else (ay if y_major else az)
                inv_big = F1 / big if big > F0 else F0
                face[i] = f
                key_s[i] = s * inv_big
                key_t[i] = t * inv_big
        else:
            for k in range(i0, i1):
                i = np.uint64(k)
                ox, oy, oz, t_far = directional_light_ray(lx, ly, lz, lifted, geo_n, smooth_n, mag, offset_ulps,
                                                          i)
                ray_o[0, i] = ox
                ray_o[1, i] = oy
                ray_o[2, i] = oz
                ray_d[0, i] = -lx
                ray_d[1, i] = -ly
                ray_d[2, i] = -lz
                t_min[i] = F0
                t_max[i] = t_far
                face[i] = 0
                key_s[i] = ox * ux + oy * uy + oz * uz
                key_t[i] = ox * vx + oy * vy + oz * vz


@helper
def _spread(v):
    """Bits of a 10-bit integer spread to the even bit positions."""
    v &= 0x3FF
    v = (v | (v << 8)) & 0x00FF00FF
    v = (v | (v << 4)) & 0x0F0F0F0F
    v = (v | (v << 2)) & 0x33333333
    v = (v | (v << 1)) & 0x55555555
    return v


def light_space_order(t_max, face, key_s, key_t, bits, n_chunks, unit_keys, key, order):
    """Active rays (t_max > 0) in order of (face, Morton cell); returns how
    many. A counting sort: one histogram per chunk, then each chunk scatters
    its rays in input order (stable). key (n,) i32: work space. unit_keys
    (a point light's cube-face coordinates, in [-1, 1]): the cells divide
    that square, and the pass that finds the keys' range is skipped (a
    scene that fills a small part of a face then falls into fewer cells,
    which measured as fast: 1-1.5 ms a light saved on hand and toys);
    else the cells divide the range the keys cover, per face.

    The chunks' passes (key range; keys and histogram; scatter) run on the
    threads (thread_pool.on_threads), each a plain kernel: as one numba
    parallel kernel of three parallel loops the sort compiled in ~3 s."""
    n = t_max.shape[0]
    threads = max(1, min(numba.get_num_threads(), n_chunks))
    lo = np.empty((n_chunks, N_FACES, 2), np.float32)
    hi = np.empty((n_chunks, N_FACES, 2), np.float32)
    if not unit_keys:
        on_threads(_key_ranges, threads, t_max, face, key_s, key_t, n_chunks, new_queue(), lo, hi)
    f_lo = np.empty((N_FACES, 2), np.float32)
    f_scale = np.empty((N_FACES, 2), np.float32)
    _face_scales(lo, hi, bool(unit_keys), bits, f_lo, f_scale)
    hist = np.empty((n_chunks, N_FACES << (2 * bits)), np.int32)
    on_threads(_keys_and_counts, threads, t_max, face, key_s, key_t, f_lo, f_scale, bits, n_chunks, new_queue(),
               key, hist)
    total = _prefix(hist)
    on_threads(_scatter, threads, key, n_chunks, new_queue(), hist, order)
    return total


@kernel
def _key_ranges(t_max, face, key_s, key_t, n_chunks, queue, lo, hi):
    """Per face, the range of the active rays' keys in each chunk this
    thread pulls (lo, hi (n_chunks, N_FACES, 2)), in thread-local rows
    first: the chunks' rows of lo/hi share cache lines."""
    n = t_max.shape[0]
    my_lo = np.empty((N_FACES, 2), np.float32)
    my_hi = np.empty((N_FACES, 2), np.float32)
    while True:
        c = next_tile(queue, n_chunks)
        if c < 0:
            break
        for f in range(N_FACES):
            for a in range(2):
                my_lo[f, a] = INF
                my_hi[f, a] = -INF
        for i in range(np.uint64(c * n // n_chunks), np.uint64((c + 1) * n // n_chunks)):
            if t_max[i] > F0:
                f = face[i]
                my_lo[f, 0] = min(my_lo[f, 0], key_s[i])
                my_hi[f, 0] = max(my_hi[f, 0], key_s[i])
                my_lo[f, 1] = min(my_lo[f, 1], key_t[i])
                my_hi[f, 1] = max(my_hi[f, 1], key_t[i])
        for f in range(N_FACES):
            for a in range(2):
                lo[c, f, a] = my_lo[f, a]
                hi[c, f, a] = my_hi[f, a]


@kernel
def _face_scales(lo, hi, unit_keys, bits, f_lo, f_scale):
    """Each face's key origin and cells per unit: over [-1, 1] for unit
    keys, else over the range the chunks' keys cover."""
    top = np.float32((1 << bits) - 1)
    for f in range(N_FACES):
        for a in range(2):
            if unit_keys:
                mn, mx = -F1, F1
            else:
                mn, mx = INF, -INF
                for c in range(lo.shape[0]):
                    mn = min(mn, lo[c, f, a])
                    mx = max(mx, hi[c, f, a])
            f_lo[f, a] = mn
            f_scale[f, a] = top / (mx - mn) if mx > mn else F0


@vector_kernel
def _keys_and_counts(t_max, face, key_s, key_t, f_lo, f_scale, bits, n_chunks, queue, key, hist):
    """Per chunk this thread pulls: keys in a branch-free loop (-1:
    inactive), then its row of the histogram (one loop doing both measured
    3.3 ms against 1.8 + 0.5 on hand at 1024^2); distinct arrays
    (vector_kernel: noalias), so that the keys' loop vectorizes."""
    n = t_max.shape[0]
    cells = 1 << (2 * bits)
    top_i = np.int32((1 << bits) - 1)
    while True:
        c = next_tile(queue, n_chunks)
        if c < 0:
            break
        for b in range(hist.shape[1]):
            hist[c, b] = 0
        for i in range(np.uint64(c * n // n_chunks), np.uint64((c + 1) * n // n_chunks)):
            f = face[i]
            # clamped: a unit key rounded past 1 (or a key outside the range
            # for any reason) must not index past its face's cells
            cu = min(max(np.int32((key_s[i] - f_lo[f, 0]) * f_scale[f, 0]), np.int32(0)), top_i)
            cv = min(max(np.int32((key_t[i] - f_lo[f, 1]) * f_scale[f, 1]), np.int32(0)), top_i)
            k = np.int32(f * cells) + (_spread(cu) | (_spread(cv) << 1))
            key[i] = k if t_max[i] > F0 else np.int32(-1)
        for i in range(np.uint64(c * n // n_chunks), np.uint64((c + 1) * n // n_chunks)):
            k = key[i]
            if k >= 0:
                hist[c, k] += 1


@kernel
def _prefix(hist):
    """Exclusive prefix in (bucket, chunk) order, in place: chunk c's rays
    of bucket k follow chunk c-1's, which keeps input order within a
    bucket. Returns the total."""
    total = 0
    for k in range(hist.shape[1]):
        for c in range(hist.shape[0]):
            count = hist[c, k]
            hist[c, k] = total
            total += count
    return total


@kernel
def _scatter(key, n_chunks, queue, hist, order):
    """Each active ray of the chunks this thread pulls to its place in order."""
    n = key.shape[0]
    while True:
        c = next_tile(queue, n_chunks)
        if c < 0:
            break
        for i in range(np.uint64(c * n // n_chunks), np.uint64((c + 1) * n // n_chunks)):
            k = key[i]
            if k >= 0:
                order[hist[c, k]] = i
                hist[c, k] += 1


class LightRays:
    """One light's shadow rays for a Surface, in structure-of-arrays form
    (with a Workspace: reused buffers, valid until the next light's rays)."""

    def __init__(self, surface, kind, light_vec, workspace=None, skip=None):
        """skip (n,) bool: samples that get no ray (their visibility is known)."""
        n = surface.mag.shape[0]
        f32 = np.float32

        # a Surface from a Workspace is a view of a buffer sized for every pixel:
        # size these alike, so that they are not reallocated as n grows
        capacity = surface.pixel.base.size if surface.pixel.base is not None else n

        def take(name, shape, dtype=f32):
            return scratch(workspace, "light." + name, shape, dtype,
                           capacity * (3 if isinstance(shape, tuple) else 1))
        self.kind = int(kind)
        self.origin = take("origin", (3, n))
        self.direction = take("direction", (3, n))
        self.t_min = take("t_min", n)
        self.t_max = take("t_max", n)
        face = take("face", n, np.int32)
        key_s = take("key_s", n)
        key_t = take("key_t", n)
        lx, ly, lz = (f32(c) for c in light_vec)
        chunks = max(1, numba.get_num_threads())
        on_threads(light_rays, max(1, min(chunks, -(-n // RAY_CHUNK))), self.kind, lx, ly, lz, surface.lifted,
                   surface.geo_n, surface.smooth_n, surface.mag, f32(EPS_OFFSET_ULPS), self.origin, self.direction,
                   self.t_min, self.t_max, face, key_s, key_t, new_queue())
        if skip is not None:
            self.t_max[skip] = -1.0
        self.order = take("order", n, np.int32)
        self.n_active = int(light_space_order(self.t_max, face, key_s, key_t, ORDER_BITS, chunks,
                                              self.kind == 0, take("key", n, np.int32), self.order)) if n else 0

    @property
    def shared_origin(self):
        return self.kind == 0
