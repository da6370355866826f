"""thread_pool.on_threads, which starts every driver's workers (one per
thread, this thread included), and the OpenMP spin default of jit/presets.py."""
import os
import subprocess
import sys
import threading
import time

import pytest

from raycore.jit.thread_pool import on_threads


def test_every_worker_runs_once_on_its_own_thread_and_results_keep_their_order():
    seen = []
    all_started = threading.Barrier(4, timeout=30)     # broken unless all four run at once

    def worker(scale, row):
        seen.append((row[0], threading.get_ident()))
        all_started.wait()
        return scale * row[0]

    rows = [[w] for w in range(4)]
    assert on_threads(worker, 4, 10, per_worker=rows) == [0, 10, 20, 30]
    assert sorted(w for w, _ in seen) == [0, 1, 2, 3]
    assert len({ident for _, ident in seen}) == 4
    assert dict(seen)[0] == threading.get_ident()          # worker 0 is the caller


def test_one_worker_runs_on_the_calling_thread():
    assert on_threads(lambda: threading.get_ident(), 1) == [threading.get_ident()]


def test_a_failing_worker_raises_only_after_every_other_has_finished():
    """No worker may still write into the caller's arrays once it has the
    exception (a Ctrl-C in the caller's share, or a bad input)."""
    done = []

    def worker(row):
        if row == 0:
            raise ValueError("worker 0 failed")
        time.sleep(0.05)
        done.append(row)

    with pytest.raises(ValueError, match="worker 0 failed"):
        on_threads(worker, 3, per_worker=[0, 1, 2])
    assert sorted(done) == [1, 2]


def test_a_pool_workers_exception_reaches_the_caller():
    def worker(row):
        if row == 1:
            raise RuntimeError("worker 1 failed")
        return row

    with pytest.raises(RuntimeError, match="worker 1 failed"):
        on_threads(worker, 2, per_worker=[0, 1])


@pytest.mark.parametrize("env, spin", [({}, "10000"), ({"GOMP_SPINCOUNT": "777"}, "777"),
                                       ({"OMP_WAIT_POLICY": "ACTIVE"}, None)])
def test_openmp_threads_spin_briefly_unless_the_user_says_otherwise(env, spin):
    base = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    out = subprocess.run([sys.executable, "-c", "import os, raycore.jit.presets; print(os.environ.get('GOMP_SPINCOUNT'))"],
                         env={**base, **env}, capture_output=True, text=True, check=True).stdout.strip()
    assert out == str(spin)
