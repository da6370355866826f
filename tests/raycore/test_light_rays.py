"""geometry/light_rays.light_space_order, the counting sort the shadow packets are
cut from: against a numpy oracle on random and on adversarial keys."""
import numpy as np
import pytest

from raycore.geometry.light_rays import N_FACES, light_space_order

BITS = 5


def _spread(v):
    v = v & 0x3FF
    v = (v | (v << 8)) & 0x00FF00FF
    v = (v | (v << 4)) & 0x0F0F0F0F
    v = (v | (v << 2)) & 0x33333333
    return (v | (v << 1)) & 0x55555555


def _sort(t_max, face, key_s, key_t, unit_keys, chunks=2):
    n = len(t_max)
    key, order = np.empty(n, np.int32), np.empty(n, np.int32)
    active = light_space_order(t_max, face, key_s, key_t, BITS, chunks, unit_keys, key, order)
    return int(active), key, order[:active]


def _check_a_stable_sort_of_the_active_rays(t_max, key, order):
    live = np.nonzero(t_max > 0)[0]
    assert sorted(order) == list(live)                          # each active ray once
    k = key[order]
    assert np.all((k >= 0) & (k < N_FACES << (2 * BITS)))       # within the buckets
    assert np.all(np.diff(k) >= 0)                              # in key order
    assert np.all(np.diff(order)[np.diff(k) == 0] > 0)          # stable: samples' order within a cell
    assert np.all(key[t_max <= 0] == -1)


@pytest.mark.parametrize("chunks", [1, 2, 7])
def test_point_light_cells_divide_each_face_exactly_as_the_oracle(rng, chunks):
    """Unit keys (a point light): cell = clamp(int((key + 1) * 31 / 2)), Morton
    interleaved, per face; keys that rounding or anything else put past
    +-1 are clamped into the face's cells."""
    n = 20000
    face = rng.integers(0, N_FACES, n).astype(np.int32)
    key_s = rng.uniform(-1, 1, n).astype(np.float32)
    key_t = rng.uniform(-1, 1, n).astype(np.float32)
    key_s[:6] = [1.0, -1.0, np.nextafter(np.float32(1), np.float32(2)), -1.5, 3.0, 0.0]
    key_t[:6] = [-1.0, 1.0, 1.0, 7.0, -2.0, 0.0]
    t_max = np.where(rng.random(n) < 0.2, -1.0, 1.0).astype(np.float32)
    t_max[:6] = 1.0
    active, key, order = _sort(t_max, face, key_s, key_t, True, chunks)
    assert active == int(np.sum(t_max > 0))
    _check_a_stable_sort_of_the_active_rays(t_max, key, order)
    top = (1 << BITS) - 1
    scale = np.float32(top / 2)
    cu = np.clip(((key_s + np.float32(1)) * scale).astype(np.int32), 0, top)
    cv = np.clip(((key_t + np.float32(1)) * scale).astype(np.int32), 0, top)
    want = face * (1 << 2 * BITS) + (_spread(cu) | (_spread(cv) << 1))
    live = t_max > 0
    np.testing.assert_array_equal(key[live], want[live])
    np.testing.assert_array_equal(order, np.nonzero(live)[0][np.argsort(want[live], kind="stable")])


def test_directional_light_cells_divide_the_range_the_keys_cover(rng):
    """Keys in world units (a directional light, any range, one face): the
    cells divide their range, the smallest key in cell 0 and the largest in
    the last; every active ray sorted once, stably."""
    n = 5000
    key_s = (rng.normal(size=n) * 1e4 + 3e5).astype(np.float32)
    key_t = (rng.normal(size=n) * 1e-3).astype(np.float32)
    face = np.zeros(n, np.int32)
    t_max = np.where(rng.random(n) < 0.1, -1.0, np.inf).astype(np.float32)
    active, key, order = _sort(t_max, face, key_s, key_t, False)
    _check_a_stable_sort_of_the_active_rays(t_max, key, order)
    live = np.nonzero(t_max > 0)[0]
    lo_s, hi_s = live[np.argmin(key_s[live])], live[np.argmax(key_s[live])]
    assert key[lo_s] & 0x55555555 == 0                  # its s cell is 0
    assert (key[hi_s] & 0x55555555) == _spread(np.array((1 << BITS) - 1))


def test_no_active_ray_and_one_ray():
    z = np.zeros(1, np.float32)
    active, _, order = _sort(np.array([-1], np.float32), np.zeros(1, np.int32), z, z, True)
    assert active == 0 and len(order) == 0
    active, key, order = _sort(np.array([2], np.float32), np.array([3], np.int32), z, z, False)
    assert active == 1 and list(order) == [0] and key[0] == 3 << (2 * BITS)
