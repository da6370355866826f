"""One packet of rays through the BVH (Wald, Boulos, Shirley 2007, "Ray
Tracing Deformable Scenes using Dynamic Bounding Volume Hierarchies"), and
one ray alone; bvh/trace.py hands the packets to the cores.

A packet of up to PACKET rays walks the tree together, nearer child first
(by the packet's summed direction's sign on the node's split axis), with a
stack. A node is skipped when
  1. its box lies outside one plane of the packet's frustum (packet_frustum:
     a cone through a shared origin, a prism along a shared direction) or,
     for other packets, interval arithmetic over the rays' origins and
     inverse directions proves no ray can enter it: a few scalar
     operations, and
  2. otherwise when no live ray's slab test hits it, tested a 16-ray chunk
     (one AVX-512 vector) at a time, branch-free within the chunk. Each
     stack entry carries the chunks that reached its parent's box (a ray
     that misses a box misses everything inside it) and the chunk that
     hit the parent: an inner node tests that chunk first and, if it hits,
     passes every chunk on, else the others in order up to the first that
     hits, passing it and every later one on (Wald 2007's first active
     ray, at the grain of a vector; starting from the parent's chunk made
     shadow packets 1-5 % faster on captured rays, the same visits), a
     leaf tests them all and keeps those that hit.
A leaf's triangles are tested against every ray of those chunks in one
vectorized loop per triangle and chunk: the watertight Woop test with one axis
permutation for the packet (the shear axis where every ray's direction is
furthest from zero) and each ray's own shear. The cheaper test by edge
planes through a shared origin (three dot products per ray) is not used:
for a ray through a mesh vertex every edge plane at that vertex contains
the ray, their signs are rounding noise, and all of them can agree, so the
ray slips through the fan (tests/raycore/test_bvh.py found 5 of 1,922 such rays);
Woop's edge functions are cross products of the vertices' sheared 2D
positions, whose rounding shrinks with the ray's distance from the vertex.
A packet's origin or direction in common gives it a frustum: shadow rays
of a point light share the light, camera rays the eye, and shadow rays of
a directional light their direction. Rays with no common shear axis are
traced one by one (trace_single, each ray's own shear), which is also the
reference the packets are checked against.

Shadow rays are any-hit: a ray is finished at its first occluder (its t_max
set to -inf, so that no box test passes for it any more), and the packet
stops once every ray is finished. Box tests are conservative: the exit
and entry distances are widened by EPS_BOX of their size (Ize 2013 bounds
the slab test's rounding by a few ulps), so rounding can only add a visit,
never lose a hit.
"""
import numpy as np

from raycore.jit.presets import flat_kernel, helper
from raycore.bvh.nodes import CHILD, COUNT
from raycore.jit.counters import CANDIDATES, PACKETS, TESTS, VISITS
from raycore.geometry.triangle import ray_axes, sheared_test, woop_test
from raycore.jit.floats import F0, F1, INF

BIG = np.float32(1e38)           # stands in for 1/0: 0 * BIG = 0 where 0 * inf is NaN
EPS_BOX = np.float32(2.0 ** -20)   # box distances widened by this fraction (~16 ulps)
EPS_PLANE = np.float32(1e-5)       # frustum planes loosened by this fraction of the magnitudes
MIN_SHEAR_SHARE = np.float32(0.5)  # a packet's shear axis holds >= half of every ray's largest component
# rays per packet: camera packets are 8x8 pixels; shadow packets of 128 rays
# (consecutive in light-space order) measured fastest of 32, 64, 128 and 256
# on every built-in scene and both light kinds (docs/performance.md)
PACKET = 128
# a packet's rays in chunks of LANES (one AVX-512 vector of float32): a node
# is tested, and a leaf's triangles intersected, only for the chunks with a
# ray that reached its parent's box
LANES = 16
N_CHUNKS = PACKET // LANES
CHUNK_BITS = 8                   # a stack entry's low bits: its chunks (N_CHUNKS <= CHUNK_BITS)
HINT_BITS = 4                    # then the chunk that hit the parent (N_CHUNKS <= 2^HINT_BITS), then the node
NODE_SHIFT = CHUNK_BITS + HINT_BITS
# rows of a packet's ray array (N_ROWS, PACKET), read-only while it walks;
# PU, PV, PK: the origin permuted to the packet's axes, SU, SV, SZ: the
# ray's shear (Woop). Hits go to separate arrays (h_t, h_b1, h_b2, prim): a store into
# the ray array inside a ray loop stops LLVM from vectorizing it (it cannot
# prove the rows disjoint)
OX, OY, OZ, DX, DY, DZ, IX, IY, IZ, TMIN, PU, PV, PK, SU, SV, SZ = range(16)
N_ROWS = 16
# packet modes
SHARED_ORIGIN, SHARED_DIRECTION, SINGLE = 0, 1, 2


@helper
def _lower(t):
    return t - abs(t) * EPS_BOX


@helper
def _upper(t):
    return t + abs(t) * EPS_BOX


@helper
def _inv(d):
    return F1 / d if d != F0 else BIG


@flat_kernel
def set_inverse(ray, n):
    """Inverse directions of rays 0..n-1 (BIG for a zero component)."""
    for r in range(n):
        ray[IX, r] = _inv(ray[DX, r])
        ray[IY, r] = _inv(ray[DY, r])
        ray[IZ, r] = _inv(ray[DZ, r])


@flat_kernel
def packet_bounds(ray, h_t, n, ia):
    """Interval-arithmetic bounds of the live rays: ia[0, a] / ia[1, a]
    origin range on axis a, ia[2, a] / ia[3, a] inverse-direction range,
    ia[4, a] 1 where every live ray's direction has one non-zero sign on a;
    ia[5, 0] / ia[5, 1] range of t_min / t_max. No live ray: t_max range empty."""
    for a in range(3):
        ia[0, a] = INF
        ia[1, a] = -INF
        ia[2, a] = INF
        ia[3, a] = -INF
        ia[4, a] = F1
    ia[5, 0] = INF
    ia[5, 1] = -INF
    px = py = pz = 0
    nx = ny = nz = 0
    live = 0
    for r in range(n):
        if not h_t[r] >= ray[TMIN, r]:
            continue
        live += 1
        for a in range(3):
            o = ray[OX + a, r]
            i = ray[IX + a, r]
            ia[0, a] = min(ia[0, a], o)
            ia[1, a] = max(ia[1, a], o)
            ia[2, a] = min(ia[2, a], i)
            ia[3, a] = max(ia[3, a], i)
        ia[5, 0] = min(ia[5, 0], ray[TMIN, r])
        ia[5, 1] = max(ia[5, 1], h_t[r])
        dx, dy, dz = ray[DX, r], ray[DY, r], ray[DZ, r]
        px += 1 if dx > F0 else 0
        py += 1 if dy > F0 else 0
        pz += 1 if dz > F0 else 0
        nx += 1 if dx < F0 else 0
        ny += 1 if dy < F0 else 0
        nz += 1 if dz < F0 else 0
    for a in range(3):
        pos = px if a == 0 else (py if a == 1 else pz)
        neg = nx if a == 0 else (ny if a == 1 else nz)
        uniform = (pos == live) | (neg == live)
        ia[4, a] = F1 if (uniform and live > 0 and np.isfinite(ia[0, a]) and np.isfinite(ia[1, a])) else F0
    return live


@flat_kernel
def packet_frustum(ray, h_t, n, mode, kx, ky, kz, big, planes):
    """Planes (nx, ny, nz, d) with n . p + d >= 0 at every point of every
    live ray's [t_min, t_max] segment, rows 0..k-1; returns k (0: none, the
    interval test alone). Shared origin L: the packet is a cone from L, and
    where every direction has one sign on the packet's shear axis K, its
    slopes s = d_U / d_K, q = d_V / d_K (the shear rows SU, SV) bound it by
    four planes through L, and t |d_K| by two planes normal to K. Shared
    direction l: the origins' extent in a basis (u, v) normal to l bounds
    the packet by four planes along l, and their least depth along l plus
    t_min by one. Column 4: how far behind a plane a box must lie to be
    culled, EPS_PLANE of the magnitudes in its test (big: the largest
    |coordinate| of any box), so that rounding never culls a box a ray
    reaches."""
    if mode == SHARED_ORIGIN:
        sign = F1 if ray[DX + kz, 0] > F0 else -F1
        s_lo = INF
        s_hi = -INF
        q_lo = INF
        q_hi = -INF
        w_lo = INF
        w_hi = -INF
        for r in range(n):
            if not h_t[r] >= ray[TMIN, r]:
                continue
            dk = ray[DX + kz, r] * sign
            if not dk > F0:
                return 0
            s = ray[SU, r] * sign
            q = ray[SV, r] * sign
            s_lo = min(s_lo, s)
            s_hi = max(s_hi, s)
            q_lo = min(q_lo, q)
            q_hi = max(q_hi, q)
            w_lo = min(w_lo, ray[TMIN, r] * dk)
            w_hi = max(w_hi, h_t[r] * dk)
        # sign * (p_K - L_K) = w, p_U - L_U = s w: planes through L in (U, K) and (V, K)
        for j in range(6):
            for c in range(4):
                planes[j, c] = F0
        planes[0, kx] = F1
        planes[0, kz] = -s_lo * sign          # p_U - L_U - s_lo w >= 0
        planes[1, kx] = -F1
        planes[1, kz] = s_hi * sign           # s_hi w - (p_U - L_U) >= 0
        planes[2, ky] = F1
        planes[2, kz] = -q_lo * sign
        planes[3, ky] = -F1
        planes[3, kz] = q_hi * sign
        planes[4, kz] = sign                  # w >= w_lo
        planes[5, kz] = -sign                 # w <= w_hi
        lx, ly, lz = ray[OX, 0], ray[OY, 0], ray[OZ, 0]
        for j in range(6):
            planes[j, 3] = -(planes[j, 0] * lx + planes[j, 1] * ly + planes[j, 2] * lz)
        planes[4, 3] -= w_lo
        planes[5, 3] += w_hi if np.isfinite(w_hi) else F0
        k = 6 if np.isfinite(w_hi) else 5
        _plane_margins(planes, k, big)
        return k
    if mode != SHARED_DIRECTION:
        return 0
    # shared direction l: a basis (u, v) normal to it
    lx, ly, lz = ray[DX, 0], ray[DY, 0], ray[DZ, 0]
    if abs(lx) < np.float32(0.6):
        ux, uy, uz = F0, lz, -ly
    else:
        ux, uy, uz = -lz, F0, lx
    vx, vy, vz = ly * uz - lz * uy, lz * ux - lx * uz, lx * uy - ly * ux
    u_lo = INF
    u_hi = -INF
    v_lo = INF
    v_hi = -INF
    w_lo = INF
    for r in range(n):
        if not h_t[r] >= ray[TMIN, r]:
            continue
        ox, oy, oz = ray[OX, r], ray[OY, r], ray[OZ, r]
        u = ox * ux + oy * uy + oz * uz
        v = ox * vx + oy * vy + oz * vz
        w = ox * lx + oy * ly + oz * lz + ray[TMIN, r]
        u_lo = min(u_lo, u)
        u_hi = max(u_hi, u)
        v_lo = min(v_lo, v)
        v_hi = max(v_hi, v)
        w_lo = min(w_lo, w)
    planes[0, 0], planes[0, 1], planes[0, 2], planes[0, 3] = ux, uy, uz, -u_lo
    planes[1, 0], planes[1, 1], planes[1, 2], planes[1, 3] = -ux, -uy, -uz, u_hi
    planes[2, 0], planes[2, 1], planes[2, 2], planes[2, 3] = vx, vy, vz, -v_lo
    planes[3, 0], planes[3, 1], planes[3, 2], planes[3, 3] = -vx, -vy, -vz, v_hi
    planes[4, 0], planes[4, 1], planes[4, 2], planes[4, 3] = lx, ly, lz, -w_lo
    _plane_margins(planes, 5, big)
    return 5


@flat_kernel
def _plane_margins(planes, k, big):
    """planes[j, 4]: the culling margin of plane j (see packet_frustum)."""
    for j in range(k):
        norm1 = abs(planes[j, 0]) + abs(planes[j, 1]) + abs(planes[j, 2])
        planes[j, 4] = EPS_PLANE * (np.float32(2.0) * norm1 * big + abs(planes[j, 3]))


@helper
def _frustum_misses(box, i, planes, n_planes):
    """True when box i lies wholly outside one of the packet's planes: its
    farthest corner along the plane's normal is behind it by more than the
    plane's margin (planes[j, 4])."""
    cx = np.float32(0.5) * (box[i, 0] + box[i, 3])
    cy = np.float32(0.5) * (box[i, 1] + box[i, 4])
    cz = np.float32(0.5) * (box[i, 2] + box[i, 5])
    ex = np.float32(0.5) * (box[i, 3] - box[i, 0])
    ey = np.float32(0.5) * (box[i, 4] - box[i, 1])
    ez = np.float32(0.5) * (box[i, 5] - box[i, 2])
    for j in range(n_planes):
        nx, ny, nz, d = planes[j, 0], planes[j, 1], planes[j, 2], planes[j, 3]
        centre = nx * cx + ny * cy + nz * cz + d
        reach = abs(nx) * ex + abs(ny) * ey + abs(nz) * ez
        if centre + reach < -planes[j, 4]:
            return True
    return False


@helper
def _ia_misses(box, i, ia):
    """True when no ray of the packet can enter box i (interval arithmetic)."""
    t_near = ia[5, 0]
    t_far = ia[5, 1]
    for a in range(3):
        if ia[4, a] == F0:
            continue
        if ia[2, a] > F0:
            near, far = box[i, a], box[i, 3 + a]
        else:
            near, far = box[i, 3 + a], box[i, a]
        n0 = (near - ia[0, a]) * ia[2, a]
        n1 = (near - ia[0, a]) * ia[3, a]
        n2 = (near - ia[1, a]) * ia[2, a]
        n3 = (near - ia[1, a]) * ia[3, a]
        f0 = (far - ia[0, a]) * ia[2, a]
        f1 = (far - ia[0, a]) * ia[3, a]
        f2 = (far - ia[1, a]) * ia[2, a]
        f3 = (far - ia[1, a]) * ia[3, a]
        t_near = max(t_near, min(min(n0, n1), min(n2, n3)))
        t_far = min(t_far, max(max(f0, f1), max(f2, f3)))
    return _lower(t_near) > _upper(t_far)


@helper
def ray_hits_box(ray, h_t, r, x0, y0, z0, x1, y1, z1):
    """True when ray r's [t_min, t_max] overlaps the box (x0, y0, z0)-(x1,
    y1, z1), its entry and exit widened by EPS_BOX (a dead ray's never does)."""
    ox, oy, oz = ray[OX, r], ray[OY, r], ray[OZ, r]
    ix, iy, iz = ray[IX, r], ray[IY, r], ray[IZ, r]
    ax = (x0 - ox) * ix
    bx = (x1 - ox) * ix
    ay = (y0 - oy) * iy
    by = (y1 - oy) * iy
    az = (z0 - oz) * iz
    bz = (z1 - oz) * iz
    t_in = _lower(max(max(min(ax, bx), min(ay, by)), min(az, bz)))
    t_out = _upper(min(min(max(ax, bx), max(ay, by)), max(az, bz)))
    return max(t_in, ray[TMIN, r]) <= min(t_out, h_t[r])


@helper
def _chunk_hits_box(ray, h_t, c0, x0, y0, z0, x1, y1, z1):
    """True when some ray of the LANES rays from c0 on has its [t_min,
    t_max] overlap the box (x0, y0, z0)-(x1, y1, z1): a branch-free loop of
    a constant LANES iterations, one AVX-512 vector."""
    hit = False
    for lane in range(LANES):
        hit = hit | ray_hits_box(ray, h_t, c0 + lane, x0, y0, z0, x1, y1, z1)
    return hit


@helper
def _chunks_hitting_box(ray, h_t, mask, box, i, exact, hint):
    """(chunks, first): of the chunks in `mask`, those that may reach box i,
    and the chunk found to hit it. Not exact (inner nodes): chunk `hint`
    (the one that hit the parent) first, and if it hits, every chunk of
    mask goes on; else the others in order up to the first that hits, which
    keeps it and every later one. Exact (leaves): every chunk is tested."""
    x0, y0, z0 = box[i, 0], box[i, 1], box[i, 2]
    x1, y1, z1 = box[i, 3], box[i, 4], box[i, 5]
    # the inner nodes' search written apart from the leaves' loop: one loop
    # serving both, with the exit inside, traced runner's captured shadow
    # rays 2-5 % slower
    if not exact:
        if (mask >> hint) & 1:
            if _chunk_hits_box(ray, h_t, hint * LANES, x0, y0, z0, x1, y1, z1):
                return mask, hint
            mask &= ~(1 << hint)
        for c in range(N_CHUNKS):
            if (mask >> c) & 1 and _chunk_hits_box(ray, h_t, c * LANES, x0, y0, z0, x1, y1, z1):
                return (mask >> c) << c, c
        return 0, 0
    out = 0
    for c in range(N_CHUNKS):
        if (mask >> c) & 1 and _chunk_hits_box(ray, h_t, c * LANES, x0, y0, z0, x1, y1, z1):
            out |= 1 << c
    return out, 0


@helper
def _push_children(stack, top, left, left_first, mask, hint):
    """Push the children of a node with the chunks that reach it and the
    chunk that hit it (an entry: node << NODE_SHIFT | hint << CHUNK_BITS |
    mask), the one to visit first on top; the new top."""
    low = (hint << CHUNK_BITS) | mask
    stack[top] = ((left + 1 if left_first else left) << NODE_SHIFT) | low
    stack[top + 1] = ((left if left_first else left + 1) << NODE_SHIFT) | low
    return top + 2


@flat_kernel
def walk_packet(bvh, ray, h_t, h_b1, h_b2, prim, n, any_hit, vis_only, mode, ia, planes, stack, counters,
                row, root):
    """Closest (or any) hits of packet rays 0..n-1 in the tree of `bvh`
    under node `root` (0: the whole; another: one instanced prototype's
    tree, raycore/instancing): on entry
    h_t holds each ray's t_max (-inf: no ray) and prim -1; on return
    prim >= 0 marks a hit (a reference), with t in h_t (closest hit; any
    hit: -inf) and barycentrics in h_b1, h_b2. mode SHARED_ORIGIN: every ray
    starts at ray[O*, 0], SHARED_DIRECTION: every ray runs along ray[D*, 0]
    (either gives the packet a frustum); anything else: interval arithmetic
    alone. vis_only (any hit, visibility alone): a hit only sets h_t to -inf
    (prim and barycentrics untouched). Returns False, tracing nothing, when
    the rays have no common shear axis (trace them one by one)."""
    box, node_i, tri, verts = bvh
    live, kx, ky, kz, sgn_x, sgn_y, sgn_z = packet_axes(ray, h_t, n)
    if live == 0:
        return True
    if kz < 0:
        return False
    sgn = (sgn_x, sgn_y, sgn_z)
    # the last chunk filled up with dead copies of ray 0 (t_max -inf: no box
    # or triangle test passes for them)
    n_pad = min(PACKET, (n + LANES - 1) // LANES * LANES)
    for r in range(n, n_pad):
        for q in range(TMIN + 1):
            ray[q, r] = ray[q, 0]
        h_t[r] = -INF
    # the rays in the frame of the Woop test: origin permuted, own shear
    row_u = OX + kx
    row_v = OX + ky
    row_k = OX + kz
    for r in range(n_pad):
        ray[PU, r] = ray[row_u, r]
        ray[PV, r] = ray[row_v, r]
        ray[PK, r] = ray[row_k, r]
    for r in range(n_pad):
        inv = F1 / ray[DX + kz, r]
        ray[SU, r] = ray[DX + kx, r] * inv
        ray[SV, r] = ray[DX + ky, r] * inv
        ray[SZ, r] = inv
    # the largest |coordinate| of the tree's root box bounds the rounding of every plane test
    big = F0
    for q in range(6):
        big = max(big, abs(box[root, q]))
    n_planes = packet_frustum(ray, h_t, n, mode, kx, ky, kz, big, planes)
    if n_planes == 0:
        packet_bounds(ray, h_t, n, ia)
    n_visits = 0
    n_tests = 0
    n_leaves = 0
    stack[0] = (root << NODE_SHIFT) | ((1 << ((n + LANES - 1) // LANES)) - 1)        # the root, every chunk
    top = 1
    while top > 0:
        top -= 1
        i = stack[top] >> NODE_SHIFT
        mask = stack[top] & ((1 << CHUNK_BITS) - 1)
        hint = (stack[top] >> CHUNK_BITS) & ((1 << HINT_BITS) - 1)
        n_visits += 1
        # the packet's frustum where it has one (tighter), else interval arithmetic
        if _frustum_misses(box, i, planes, n_planes) if n_planes > 0 else _ia_misses(box, i, ia):
            continue
        c = node_i[i, COUNT]
        # inner nodes: the parent's chunk, else up to the first chunk that
        # hits; leaves: every chunk, which the triangle tests then skip
        mask, hint = _chunks_hitting_box(ray, h_t, mask, box, i, c > 0, hint)
        if mask == 0:
            continue
        if c <= 0:
            left = node_i[i, CHILD]
            if left < 0:
                continue
            top = _push_children(stack, top, left, sgn[-1 - c], mask, hint)
            continue
        n_leaves += 1
        ref0 = node_i[i, CHILD]
        # every ray of the chunks that reach the leaf, a vector at a time: a
        # loop over only the rays that reach it (from an offset index)
        # measured 1.7x slower than a vectorized one over the packet
        for k in range(ref0, ref0 + c):
            v = (verts[k, 0], verts[k, 1], verts[k, 2], verts[k, 3], verts[k, 4], verts[k, 5],
                 verts[k, 6], verts[k, 7], verts[k, 8])
            ax, ay, az = v[kx], v[ky], v[kz]
            bx, by, bz = v[3 + kx], v[3 + ky], v[3 + kz]
            cx, cy, cz = v[6 + kx], v[6 + ky], v[6 + kz]
            # an or-reduction, not a count: an int64 count halves the vector width
            some = False
            for ch in range(N_CHUNKS):
                if not (mask >> ch) & 1:
                    continue
                n_tests += LANES
                c0 = ch * LANES
                if vis_only:
                    # shadow rays: only whether something is hit (one store, not four)
                    for lane in range(LANES):
                        r = c0 + lane
                        ou, ov, ok = ray[PU, r], ray[PV, r], ray[PK, r]
                        hit, t, _b1, _b2 = woop_test(ax - ou, ay - ov, az - ok, bx - ou, by - ov, bz - ok,
                                                     cx - ou, cy - ov, cz - ok, ray[SU, r], ray[SV, r],
                                                     ray[SZ, r])
                        hit = hit & (t > ray[TMIN, r]) & (t < h_t[r])
                        some = some | hit
                        h_t[r] = -INF if hit else h_t[r]
                else:
                    for lane in range(LANES):
                        r = c0 + lane
                        ou, ov, ok = ray[PU, r], ray[PV, r], ray[PK, r]
                        hit, t, b1, b2 = woop_test(ax - ou, ay - ov, az - ok, bx - ou, by - ov, bz - ok,
                                                   cx - ou, cy - ov, cz - ok, ray[SU, r], ray[SV, r], ray[SZ, r])
                        hit = hit & (t > ray[TMIN, r]) & (t < h_t[r])
                        some = some | hit
                        h_t[r] = (-INF if any_hit else t) if hit else h_t[r]
                        h_b1[r] = b1 if hit else h_b1[r]
                        h_b2[r] = b2 if hit else h_b2[r]
                        prim[r] = k if hit else prim[r]
            if any_hit and some:
                live = 0
                for r in range(n):
                    live += 1 if h_t[r] >= ray[TMIN, r] else 0
        if any_hit and live <= 0:
            break
    counters[row, PACKETS] += 1
    counters[row, VISITS] += n_visits
    counters[row, TESTS] += n_tests
    counters[row, CANDIDATES] += n_leaves
    return True


@flat_kernel
def packet_axes(ray, h_t, n):
    """(live, kx, ky, kz, sx, sy, sz): how many rays are live; the Woop
    test's axis permutation for the whole packet; whether the packet's
    summed direction is >= 0 on each axis (the nearer child first). kz is
    the axis of the summed direction's largest component, or the next,
    where every live ray keeps at least MIN_SHEAR_SHARE of its own largest
    component (the test stays as accurate as with the ray's own largest: a
    small one makes the shear, and the distance to a triangle that is all
    but degenerate, noise); kz = -1 when no axis qualifies (trace the rays
    one by one)."""
    live = 0
    sum_x = F0
    sum_y = F0
    sum_z = F0
    for r in range(n):
        ok = h_t[r] >= ray[TMIN, r]
        live += 1 if ok else 0
        sum_x += ray[DX, r] if ok else F0
        sum_y += ray[DY, r] if ok else F0
        sum_z += ray[DZ, r] if ok else F0
    big = (abs(sum_x), abs(sum_y), abs(sum_z))
    first = 0 if big[0] >= big[1] and big[0] >= big[2] else (1 if big[1] >= big[2] else 2)
    kz = -1
    for step in range(3):
        a = (first + step) % 3
        fits = True
        for r in range(n):
            dx, dy, dz = abs(ray[DX, r]), abs(ray[DY, r]), abs(ray[DZ, r])
            d_a = dx if a == 0 else (dy if a == 1 else dz)
            bad = (d_a < MIN_SHEAR_SHARE * max(dx, max(dy, dz))) & (h_t[r] >= ray[TMIN, r])
            fits = fits & (not bad)
        if fits:
            kz = a
            break
    return live, (kz + 1) % 3, (kz + 2) % 3, kz, sum_x >= F0, sum_y >= F0, sum_z >= F0


@flat_kernel
def trace_single(bvh, ox, oy, oz, dx, dy, dz, t_min, t_max, any_hit, stack, counters, row, root):
    """One ray through the tree under node `root`, Woop test with its own
    shear: (t, ref, b1, b2), ref -1 on a miss (t_max then). The reference
    the packets are checked against."""
    box, node_i, tri, verts = bvh
    o = (ox, oy, oz)
    d = (dx, dy, dz)
    inv = (_inv(dx), _inv(dy), _inv(dz))
    kx, ky, kz = ray_axes(dx, dy, dz)
    s_z = F1 / d[kz]
    s_x = d[kx] * s_z
    s_y = d[ky] * s_z
    best_t, best_k, best_b1, best_b2 = t_max, -1, F0, F0
    stack[0] = root
    top = 1
    while top > 0:
        top -= 1
        i = stack[top]
        counters[row, VISITS] += 1
        t_in = -INF
        t_out = INF
        for a in range(3):
            ta = (box[i, a] - o[a]) * inv[a]
            tb = (box[i, 3 + a] - o[a]) * inv[a]
            t_in = max(t_in, min(ta, tb))
            t_out = min(t_out, max(ta, tb))
        if not max(_lower(t_in), t_min) <= min(_upper(t_out), best_t):
            continue
        c = node_i[i, COUNT]
        if c <= 0:
            left = node_i[i, CHILD]
            if left < 0:
                continue
            left_first = d[-1 - c] >= F0
            stack[top] = left + 1 if left_first else left
            stack[top + 1] = left if left_first else left + 1
            top += 2
            continue
        counters[row, CANDIDATES] += 1
        first = node_i[i, CHILD]
        for k in range(first, first + c):
            counters[row, TESTS] += 1
            hit, t, b1, b2 = sheared_test(verts, k, o, kx, ky, kz, s_x, s_y, s_z)
            if hit and t > t_min and t < best_t:
                best_t, best_k, best_b1, best_b2 = t, k, b1, b2
                if any_hit:
                    return best_t, best_k, best_b1, best_b2
    return best_t, best_k, best_b1, best_b2


