"""Python worker threads for work beside numba's own threads: kernels that
release the GIL (the BVH build's tasks, bvh_build.py) and calls into C
that do (the EXR encoder's deflate, exr_zip.py).

One pool per name, made when first asked for and kept: starting threads
per call would cost more than the work. A pool inherited through fork has
no threads behind it (its jobs would wait forever), so a child makes its own.
"""
import os
from concurrent.futures import ThreadPoolExecutor

_POOLS = {}          # name -> (pool, the pid that made it)


def thread_pool(name: str, n_workers: int) -> ThreadPoolExecutor:
    """A pool of at least n_workers threads named `name`, made once per process."""
    pool, pid = _POOLS.get(name, (None, None))
    if pool is None or pid != os.getpid() or pool._max_workers < n_workers:
        pool = ThreadPoolExecutor(n_workers, thread_name_prefix=name)
        _POOLS[name] = (pool, os.getpid())
    return pool
