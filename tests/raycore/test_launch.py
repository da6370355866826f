"""jit/launch.py: a parallel loop calling a worker kernel through its native
entry point, as the camera rays and the sweep are started."""
import numpy as np
import pytest
from numba import njit, prange

from raycore.jit.launch import call_native, check_workers, native_entry, value_kind


@njit(nogil=True)
def _fill_row(row, start, step):
    if step < 0:
        raise ValueError("negative step")
    for i in range(row.shape[0]):
        row[i] = start + step * i


@njit(parallel=True)
def _fill_rows_on_threads(entry, ok, rows, start, step):
    for w in prange(rows.shape[0]):
        ok[w] = call_native(entry, (rows[w], start + w, step))


def test_every_row_is_filled_by_the_worker_called_through_its_address():
    rows = np.zeros((5, 7), np.float64)
    ok = np.zeros(5, np.bool_)
    _fill_rows_on_threads(native_entry(_fill_row, rows[0], 0.0, 0.5), ok, rows, 0.0, 0.5)
    np.testing.assert_array_equal(rows, np.arange(5)[:, None] + 0.5 * np.arange(7)[None, :])
    assert ok.all()
    check_workers(_fill_row, ok)


def test_a_worker_that_raises_is_reported_not_lost():
    rows = np.zeros((3, 4), np.float64)
    ok = np.ones(3, np.bool_)
    _fill_rows_on_threads(native_entry(_fill_row, rows[0], 0.0, -1.0), ok, rows, 0.0, -1.0)
    assert not ok.any()
    with pytest.raises(RuntimeError, match="_fill_row failed on 3 of 3 threads"):
        check_workers(_fill_row, ok)


def test_the_entry_is_that_of_the_arguments_types():
    a, b = np.zeros(3, np.float64), np.zeros(3, np.float32)
    assert native_entry(_fill_row, a, 0.0, 1.0) == native_entry(_fill_row, a, 2.0, 3.0)
    assert native_entry(_fill_row, a, 0.0, 1.0) != native_entry(_fill_row, b, np.float32(0), np.float32(1))


def test_a_worker_that_returns_a_value_is_refused():
    @njit
    def worker(x):
        return x + 1

    with pytest.raises(TypeError, match="returns nothing"):
        native_entry(worker, 1)


def test_value_kind_tells_apart_what_numba_types_apart():
    """native_entry keeps addresses by value_kind (numba.typeof over a
    driver's ~30 arguments took 0.36 ms a pass): values numba types apart
    must have kinds apart (a kind may be finer than numba's type: a Python
    float and a numpy float64 are apart), and values of one kind one numba type."""
    import numba
    from raycore.bvh.nodes import empty_bvh
    bvh = empty_bvh(1, 0)
    lights = np.zeros((2, 4), np.float32)
    rows = np.arange(2, dtype=np.int64)
    frozen = lights.copy()
    frozen.flags.writeable = False
    values = (lights, frozen, np.asfortranarray(np.zeros((4, 2), np.float32)), lights[:, :3],
              lights.astype(np.float64), lights[0], np.float32(1), np.float64(1), 1.0, 1, 2 ** 63, True, np.bool_(1),
              (lights, rows), (rows, lights), bvh)
    kinds = [value_kind(v) for v in values]
    assert len(set(kinds)) == len(values)
    # and numba agrees wherever two kinds are the same
    for v, w in ((lights, lights.copy()), (1, 5), ((rows, 1.0), (rows[::-1].copy(), 2.0)), (bvh, empty_bvh(3, 2))):
        assert value_kind(v) == value_kind(w) and numba.typeof(v) == numba.typeof(w)
    assert value_kind(object()) is None and value_kind([1]) is None
