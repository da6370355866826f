"""Where each frame goes (output.path's '#' run), which channels it has, and
which frames a run must render (--resume and --overwrite)."""
import os
import re
from pathlib import Path

from anim.errors import SceneError
from raycore.config import RenderConfig

from anim.render.output_dir import file_crc32, whole_frame


def split_pattern(pattern: str):
    """(head, width, tail) around output.path's (last) run of '#', or None
    when it has none."""
    runs = re.findall(r"#+", pattern)
    if not runs:
        return None
    head, _, tail = pattern.rpartition(runs[-1])
    return head, len(runs[-1]), tail


def frame_path(pattern: str, frame: int) -> str:
    """Replace the run of '#' (the schema allows one) with the frame number,
    zero-padded to the run's width; a negative frame gets its sign in front
    of the padded digits (frame -1 in f_###.exr: f_-001.exr)."""
    parts = split_pattern(pattern)
    if parts is None:
        return pattern
    head, width, tail = parts
    return f"{head}{'-' if frame < 0 else ''}{abs(frame):0{width}d}{tail}"


def frame_channels(cfg: RenderConfig) -> list:
    """The EXR channels a frame of this render has (SPEC section 4)."""
    extra = {"N": ["N.X", "N.Y", "N.Z"], "P": ["P.X", "P.Y", "P.Z"], "id": ["id"]}
    return ["R", "G", "B", "A", "Z"] + [c for a in cfg.aovs for c in extra[a]]


def frame_file(scene, out_dir, frame) -> Path:
    """Where frame `frame` goes: output.path's name in out_dir, or
    output.path itself, relative to the scene file."""
    path = Path(frame_path(scene.spec.output.path, frame))
    if out_dir is not None:
        return out_dir / path.name
    return path if path.is_absolute() else scene.path.parent / path


def frames_dir(scene, out_dir, first_frame) -> Path:
    """The folder the frames go to: --out-dir, else output.path's folder
    (relative to the scene file)."""
    if out_dir is not None:
        return Path(out_dir)
    first = Path(frame_path(scene.spec.output.path, first_frame))
    return first.parent if first.is_absolute() else scene.path.parent / first.parent


def existing_frames(scene, out_dir, frames) -> dict:
    """{frame: path} of the files of `frames` that exist, from one listing of
    the frames' directory: a stat per frame made a 10,000,000-frame range
    take minutes before its first frame."""
    if len(frames) == 0:
        return {}
    directory = frame_file(scene, out_dir, frames[0]).parent
    pattern = Path(scene.spec.output.path).name
    parts = split_pattern(pattern)
    if parts is None:
        path = frame_file(scene, out_dir, frames[0])
        return {frames[0]: path} if path.exists() else {}
    head, _, tail = parts
    number = re.compile(re.escape(head) + r"(-?[0-9]+)" + re.escape(tail) + "$")
    found = {}
    try:
        entries = list(os.scandir(directory))
    except (FileNotFoundError, NotADirectoryError):
        return {}
    for entry in entries:
        m = number.match(entry.name)
        if m is None:
            continue
        f = int(m.group(1))
        if f in frames and frame_path(pattern, f) == entry.name and not entry.is_dir():
            found[f] = directory / entry.name
    return found


class FramePlan:
    """The (frame, path) pairs a run renders, in frame order, made lazily:
    the frames of the range that are not finished. Only the files that
    exist are looked at, so a range of millions of frames is planned in the
    time of one directory listing. Without --resume or --overwrite an
    existing frame is an error, raised here, before any work. With --resume
    an existing frame is checked when the run reaches it (whole_frame: the
    checksum stats.json recorded, `checksums`, or a full decode) and
    skipped if whole, else rendered again, said through `warn`."""

    def __init__(self, scene, out_dir, frames, resume, overwrite, cfg=None, warn=None, checksums=None):
        pattern = scene.spec.output.path
        if "#" not in pattern and len(frames) > 1:
            raise SceneError(scene.path, "output.path", "needs a run of '#' for the frame number when rendering several frames")
        self.scene, self.out_dir, self.frames, self.cfg = scene, out_dir, frames, cfg
        self.warn, self.checksums = warn, checksums or {}
        self.directory = frame_file(scene, out_dir, frames[0]).parent if len(frames) else None
        self.stale = set()                  # existing files to be rendered again
        self.finished = set()               # existing frames checked whole
        self.verified = {}                  # frame: CRC-32 of the ones checked by a full decode
        self.existing = existing_frames(scene, out_dir, frames)
        if overwrite:
            self.stale = set(self.existing.values())
            self.existing = {}
        elif self.existing and not resume:
            path = self.existing[min(self.existing)]
            raise SceneError(path, "", "frame exists; use --resume to skip finished frames or --overwrite to replace them")
        self._first = None

    def _finished(self, f) -> bool:
        if f in self.finished:
            return True
        path = self.existing.pop(f, None)
        if path is None:
            return False
        cfg = self.cfg
        known = self.checksums.get(f)
        problem = whole_frame(path, cfg.width, cfg.height, frame_channels(cfg), known) if cfg else ""
        if not problem:
            self.finished.add(f)
            if known is None and cfg:
                # decoded whole: its checksum spares the next --resume the decode
                self.verified[f] = file_crc32(path)
            return True
        if self.warn:
            self.warn(f"{path}: {problem}; rendering frame {f} again")
        self.stale.add(path)
        return False

    def __iter__(self):
        for f in self.frames:
            if not self._finished(f):
                yield f, frame_file(self.scene, self.out_dir, f)

    def first(self):
        """The first (frame, path) to render, or None (checks the frames before it)."""
        if self._first is None:
            self._first = next(iter(self), False)
        return self._first or None


def plan_frames(scene, out_dir, frames, resume, overwrite, cfg=None, warn=None, checksums=None) -> FramePlan:
    return FramePlan(scene, out_dir, frames, resume, overwrite, cfg, warn, checksums)
