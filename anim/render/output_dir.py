"""The output directory's bookkeeping, so that nothing finished is lost and
nothing broken is left, across kills, resumes and renders running side by
side:

* whole_frame: a frame file is only "done" if it is an EXR of this render's
  size and channels whose last scanline chunk reads back (a file cut short
  by a crash or a full disk, or one written by something else, is not);
* remove_stale_temps: a frame is written under `.NAME.PID.tmp.exr` and
  renamed into place (raycore/images/image_io.py), stats.json and claims likewise
  under `.NAME.PID.tmp`; such a file whose process is gone is a leftover of
  a kill and is removed;
* claims: before a render starts a frame it creates `.NAME.claim` (O_EXCL:
  one winner), holding host and PID, and removes it when the frame is
  written. Two `--resume` renders into one directory thus share the frames
  (each skips the other's claims), as Blender's placeholders allow. A claim
  of a process that is gone (same host) or older than CLAIM_STALE_S (another
  host, which cannot be asked) is taken over.
"""
import os
import re
import socket
import time
import zlib
from pathlib import Path

import OpenImageIO as oiio

CLAIM_STALE_S = 600.0
_TEMP = re.compile(r"^\..+\.(\d+)\.tmp(\.exr)?$")     # frames, claims and stats being written


def file_crc32(path) -> int:
    """CRC-32 of a file's bytes (about 1 ms for a 1024^2 frame): the
    checksum stats.json keeps per frame, which --resume compares."""
    with open(path, "rb") as f:
        return zlib.crc32(f.read())


def whole_frame(path: Path, width: int, height: int, channels, crc32=None) -> str:
    """'' if `path` is a complete frame of this size with these channels,
    else the reason it is not. The header and the last scanline are read
    always; then, with the checksum stats.json recorded when the frame was
    written, the bytes are compared with it (~1 ms at 1024^2), and without
    one (a frame of a run that was killed before its stats were written)
    every pixel is decoded (~57 ms at 1024^2, against ~300 ms to render and
    write the frame): a frame with bytes flipped in its
    middle kept its size and its last scanline, and no reader could open it."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return f"not a readable EXR ({oiio.geterror().strip() or 'unknown format'})"
    try:
        spec = inp.spec()
        if (spec.width, spec.height) != (width, height):
            return f"is {spec.width}x{spec.height}, this render is {width}x{height}"
        missing = [c for c in channels if c not in spec.channelnames]
        if missing:
            return f"lacks channel(s) {', '.join(missing)}"
        if inp.read_scanline(spec.y + spec.height - 1, 0, "float") is None:
            return f"is cut short ({inp.geterror().strip() or 'last scanline unreadable'})"
        if crc32 is not None:
            return "" if file_crc32(path) == crc32 else "its bytes differ from those written (checksum)"
        if inp.read_image(0, 0, 0, -1, "float") is None:
            return f"cannot be decoded ({inp.geterror().strip() or 'corrupt data'})"
        return ""
    finally:
        inp.close()


def process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:            # exists, owned by someone else
        return True
    return True


def remove_stale_temps(directory: Path) -> list:
    """Remove the temporary files and the claims in `directory` whose process
    is gone (a claim's frame may have been written just before the kill, so
    no later run would claim, and release, it again); returns their names."""
    removed = []
    if not directory.is_dir():
        return removed
    for entry in directory.iterdir():
        m = _TEMP.match(entry.name)
        stale = (m and int(m.group(1)) != os.getpid() and not process_alive(int(m.group(1)))) or \
            (entry.name.startswith(".") and entry.name.endswith(".claim") and _claim_is_stale(entry))
        if stale:
            try:
                entry.unlink()
                removed.append(entry.name)
            except FileNotFoundError:
                pass
            except PermissionError:      # a directory we only read (nothing left to render there)
                pass
    return removed


def claim_path(frame_path: Path) -> Path:
    return frame_path.with_name(f".{frame_path.name}.claim")


def _claim_is_stale(path: Path) -> bool:
    try:
        host, pid, _ = path.read_text().split()
        age = time.time() - path.stat().st_mtime
    except (OSError, ValueError):
        return True                    # unreadable or half-written: its writer died at once
    if host == socket.gethostname():
        return not process_alive(int(pid))
    return age > CLAIM_STALE_S


def claim(frame_path: Path) -> bool:
    """Claim the frame for this process; False if a live render holds it.
    The claim appears with its content in one step (written aside, then
    hard-linked into place, which fails if a claim exists), so no render
    ever reads a half-written claim and takes it for a dead one."""
    path = claim_path(frame_path)
    mine = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    mine.write_text(f"{socket.gethostname()} {os.getpid()} {time.time():.0f}\n")
    try:
        for _ in range(2):
            try:
                os.link(mine, path)
                return True
            except FileExistsError:
                if not _claim_is_stale(path):
                    return False
                try:
                    path.unlink()      # taken over; if another render races us here, the link decides
                except FileNotFoundError:
                    pass
        return False
    finally:
        mine.unlink()


def release(frame_path: Path) -> None:
    try:
        claim_path(frame_path).unlink()
    except FileNotFoundError:
        pass
