"""One cold warm-up at a time on a machine: the workers of a cluster that run
on one machine share numba's cache, and on a cold cache each of them
compiled every kernel at once (`render --workers 2` of the demo on 2 cores:
48.6 s and 90 s of CPU, where one render compiles in ~18 s; with more
workers, more copies of the compiler's memory too).

The first worker to warm up a kernel set (this package's build, the scene
and its settings) does it under an exclusive file lock and then leaves a
marker; a worker that finds the marker warms up at once (its kernels load
from the cache), and one that finds the lock held waits for it, finds the
marker and goes on. Without frustrace's cache directory
(FRUSTRACE_CACHE_DIR set empty) or a file lock (not POSIX), every worker
warms up at once, as before."""
import hashlib
import os

from anim.io.mesh_cache import cache_root

try:
    import fcntl
except ImportError:              # not POSIX: no lock
    fcntl = None


def warm_once(key: str, warm):
    """warm(), the warm-up of the kernel set named by key; under the machine's
    warm-up lock unless a marker says the set was warmed up before. Returns
    what warm() returns."""
    from raycore.jit.kernel_cache import PACKAGE_STAMP, RAYCORE
    root = cache_root()
    if root is None or fcntl is None:
        return warm()
    folder = root / "warm"
    # numba's cache for this build: the package's bytes and where it lies
    # (its own __pycache__) or NUMBA_CACHE_DIR
    where = f"{PACKAGE_STAMP}\0{RAYCORE}\0{os.environ.get('NUMBA_CACHE_DIR', '')}"
    name = hashlib.sha256(f"{where}\0{key}".encode()).hexdigest()[:24]
    marker = folder / f"{name}.done"
    if marker.exists():
        return warm()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        lock = open(folder / "warm-up.lock", "a+")
    except OSError:              # a read-only cache: as if there were none
        return warm()
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if not marker.exists():
                result = warm()
                try:
                    marker.touch()
                except OSError:
                    pass
                return result
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
    return warm()


__all__ = ["warm_once"]
