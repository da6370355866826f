"""numba's on-disk cache, made stale by an edit to any kernel source.

numba checks a cached kernel against the bytes of the one file that
defines it. A kernel also bakes in what it reads from other modules:
constants (`PACKET` of bvh/packets.py, read by bvh/trace.py's drivers) and
the inlined helpers it calls. After an edit to one of those, the unchanged
file's cached machine code is loaded with the old values; a packet size
changed in bvh/packets.py alone made the shadow driver write past a
buffer sized with the new one (heap corruption). The same
happens to a user whose upgrade leaves one module's bytes as they were.

So every cache entry also carries PACKAGE_STAMP, a hash of every module of
raycore and of every anim module that defines kernels (those that import
raycore.jit.presets): an edit to any of them recompiles every kernel once, and
nothing stale is ever loaded. The locators are numba's own (NUMBA_CACHE_DIR,
the source tree's __pycache__, the user-wide directory), with this stamp
beside their per-file one.
"""
import hashlib
from pathlib import Path

from numba.core import caching

RAYCORE = Path(__file__).resolve().parents[1]
KERNEL_MARK = "raycore.jit.presets import"


def kernel_sources(root: Path) -> list:
    """The files whose bytes a kernel of root/raycore or root/anim can bake
    in: every module of raycore and its sub-packages, and every module of
    anim (at any depth) that defines kernels."""
    anim = sorted(p for p in (root / "anim").rglob("*.py") if KERNEL_MARK in p.read_text(encoding="utf-8"))
    return sorted((root / "raycore").rglob("*.py")) + anim


def package_stamp(root: Path) -> str:
    """sha256 over the kernel sources' paths (relative to root) and bytes."""
    h = hashlib.sha256()
    for path in kernel_sources(root):
        h.update(f"{path.relative_to(root).as_posix()}\0".encode())
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


PACKAGE_STAMP = package_stamp(RAYCORE.parent)


def _stamped(locator):
    """numba's locator `locator`, its source stamp paired with PACKAGE_STAMP."""
    class Stamped(locator):
        def get_source_stamp(self):
            return super().get_source_stamp(), PACKAGE_STAMP
    Stamped.__name__ = Stamped.__qualname__ = f"Stamped{locator.__name__}"
    return Stamped


def _numba(name):
    """A class of numba's caching module (private names lost their leading
    underscore in recent numba)."""
    return getattr(caching, name, None) or getattr(caching, "_" + name)


def install():
    """Put stamped twins of numba's locators of a file-backed function first,
    in numba's order of preference (once; before any kernel is decorated)."""
    classes = _numba("CacheImpl")._locator_classes
    if not any(getattr(c, "__name__", "").startswith("Stamped") for c in classes):
        classes[:0] = [_stamped(_numba(n)) for n in
                       ("UserProvidedCacheLocator", "InTreeCacheLocator", "UserWideCacheLocator")]


install()
