"""Output paths checked before any work starts.

A render, bench or preview that runs for minutes and then cannot write its
result has wasted the minutes: every output path (frames directory, stats,
JSON, plots, previews) is created and probed for writing first, and a
problem is a SceneError (exit 2, one line naming the path), never an
internal error after the work.
"""
import os
import tempfile
from pathlib import Path

from anim.errors import SceneError

PREVIEW_FORMATS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr", ".bmp", ".webp")


def writable_dir(directory: Path, what: str) -> Path:
    """Create `directory` (and its parents) and check that a file can be
    created in it; SceneError naming it otherwise."""
    directory = Path(directory)
    for parent in [directory, *directory.parents]:
        if parent.exists() and not parent.is_dir():
            raise SceneError(parent, "", f"is a file, so {what} cannot go under it")
    try:
        directory.mkdir(parents=True, exist_ok=True)
        # named like the other temporaries (.NAME.PID.tmp): if a kill lands
        # between its creation and its removal, the next run removes it
        fd, probe = tempfile.mkstemp(prefix=".frustrace-probe.", suffix=f".{os.getpid()}.tmp", dir=directory)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise SceneError(directory, "", f"cannot write {what} here: {exc.strerror or exc}") from None
    return directory


def writable_file(path: Path, what: str, suffixes=None) -> Path:
    """Check that `path` can be written (its directory made and probed, not a
    directory itself, and one of `suffixes` if given) before the work."""
    path = Path(path)
    if suffixes and path.suffix.lower() not in suffixes:
        raise SceneError(path, "", f"{what} must be one of {', '.join(suffixes)}")
    if path.is_dir():
        raise SceneError(path, "", f"is a directory; {what} needs a file name")
    writable_dir(path.parent if str(path.parent) else Path("."), what)
    return path
