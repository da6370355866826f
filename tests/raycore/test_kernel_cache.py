"""numba's cache is stale once any kernel source changes (raycore/jit/kernel_cache.py):
a kernel's cached machine code bakes in constants and helpers of other
modules, which numba's own per-file check does not see."""
import importlib
import pkgutil
import shutil
from pathlib import Path

import anim
import raycore
from raycore.jit.kernel_cache import PACKAGE_STAMP, kernel_sources, package_stamp

ROOT = Path(__file__).resolve().parents[2]


def _dispatchers():
    """Every cached numba kernel of raycore and of anim's modules."""
    found = []
    for package in (raycore, anim):
        for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            module = importlib.import_module(info.name)
            for value in vars(module).values():
                if getattr(value, "_cache", None) is not None and hasattr(value, "py_func") \
                        and value.py_func.__module__ == module.__name__:
                    found.append(value)
    return found


def test_every_cached_kernel_carries_the_package_stamp():
    kernels = _dispatchers()
    assert len(kernels) > 40
    for k in kernels:
        locator = k._cache._impl.locator
        assert type(locator).__name__.startswith("Stamped"), (k, type(locator))
        file_stamp, stamp = locator.get_source_stamp()
        assert stamp == PACKAGE_STAMP and len(file_stamp) == 32


def test_an_edit_to_any_kernel_source_changes_the_stamp_and_nothing_else_does(tmp_path):
    """A copy of the tree: the stamp is the tree's; an edit to a constant of
    bvh/packets.py (read by bvh/trace.py's kernels), to config.py (no kernel,
    constants only) or to an anim kernel module changes it; an edit to an
    anim module without kernels, or to the CLI, does not."""
    for part in ("raycore", "anim", "cli"):
        shutil.copytree(ROOT / part, tmp_path / part, ignore=shutil.ignore_patterns("__pycache__", "*.nb?"))
    assert package_stamp(tmp_path) == PACKAGE_STAMP
    names = {p.relative_to(tmp_path).as_posix() for p in kernel_sources(tmp_path)}
    assert {"raycore/bvh/packets.py", "raycore/config.py", "raycore/jit/presets.py",
            "anim/track_kernels.py"} <= names
    assert "anim/scene.py" not in names

    def edited(rel, old, new):
        path = tmp_path / rel
        text = path.read_text()
        assert old in text, (rel, old)
        path.write_text(text.replace(old, new, 1))
        stamp = package_stamp(tmp_path)
        path.write_text(text)
        return stamp
    assert edited("raycore/bvh/packets.py", "PACKET = 128", "PACKET = 256") != PACKAGE_STAMP
    # a module two packages deep, and one of a sub-package that defines no kernel
    assert edited("raycore/grid/cgt.py", "\n", "\n# edited\n") != PACKAGE_STAMP
    assert edited("raycore/jit/floats.py", "\n", "\n# edited\n") != PACKAGE_STAMP
    assert edited("raycore/config.py", "\n", "\n# edited\n") != PACKAGE_STAMP
    assert edited("anim/track_kernels.py", "\n", "\n# edited\n") != PACKAGE_STAMP
    assert edited("anim/scene.py", "\n", "\n# edited\n") == PACKAGE_STAMP
    assert edited("cli/main.py", "\n", "\n# edited\n") == PACKAGE_STAMP
    assert package_stamp(tmp_path) == PACKAGE_STAMP


def test_a_cache_entry_of_another_stamp_is_not_loaded():
    """A kernel cached under this stamp loads; its very files read as another
    version of some other module would (another package stamp) are stale:
    numba compiles instead of loading them."""
    from numba.core.caching import IndexDataCacheFile
    from raycore.jit.tile_queue import tile_count
    assert tile_count(100, 50, 16) == (7, 28)         # compiled or loaded, and saved
    index = tile_count._cache._cache_file
    assert index._load_index(), "the kernel's cache entry is missing"
    file_stamp, stamp = index._source_stamp
    assert stamp == PACKAGE_STAMP
    base = index._index_name[:-len(".nbi")]
    assert IndexDataCacheFile(index._cache_path, base, (file_stamp, stamp))._load_index()
    assert IndexDataCacheFile(index._cache_path, base, (file_stamp, "another version"))._load_index() == {}
