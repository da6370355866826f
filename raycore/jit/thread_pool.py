"""Python worker threads for kernels that release the GIL (the drivers'
workers, on_threads; the BVH build's tasks, bvh/build.py) and for calls
into C that do (the EXR encoder's deflate, images/exr_zip.py).

One pool per name, made when first asked for and kept: starting threads
per call would cost more than the work. A pool inherited through fork has
no threads behind it (its jobs would wait forever), so a child makes its own.
"""
import os
from concurrent.futures import ThreadPoolExecutor, wait

_POOLS = {}          # name -> (pool, the pid that made it)


def thread_pool(name: str, n_workers: int) -> ThreadPoolExecutor:
    """A pool of at least n_workers threads named `name`, made once per process."""
    pool, pid = _POOLS.get(name, (None, None))
    if pool is None or pid != os.getpid() or pool._max_workers < n_workers:
        pool = ThreadPoolExecutor(n_workers, thread_name_prefix=name)
        _POOLS[name] = (pool, os.getpid())
    return pool


def on_threads(worker, n_workers, *args, per_worker=None):
    """worker(*args) on n_workers threads at once (this one and n_workers - 1
    of a pool), for a nogil kernel whose workers pull their work from one
    queue among args; with per_worker, worker w gets per_worker[w] as its
    last argument. Returns the workers' results, in order.

    This is how the drivers start their workers instead of a numba prange
    over them (the camera rays and the sweep, which every frame takes, use
    jit/launch.py instead: OpenMP's threads without the prange's compile): a
    parallel kernel is optimized by LLVM again as a whole, with every stage
    it calls, and its parfor costs more compile time than
    the work it starts (the sweep of sweep.py compiled in 36 s that
    way, 22 s this way), while the workers run as fast to within the
    host's noise (docs/performance.md, compile time; OpenMP's idle threads spin only briefly, jit/presets.py, so that
    they do not hold the cores these threads need)."""
    def call(w):
        return worker(*args, per_worker[w]) if per_worker is not None else worker(*args)

    if n_workers <= 1:
        return [call(0)]
    pool = thread_pool("workers", n_workers - 1)
    others = [pool.submit(call, w) for w in range(1, n_workers)]
    try:
        first = call(0)
    finally:
        wait(others)          # no worker is left writing into the caller's arrays
    return [first] + [f.result() for f in others]
