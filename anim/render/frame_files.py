"""Where each frame goes (output.path's '#' run), which channels it has, and
which frames a run must render (--resume and --overwrite)."""
import re
from pathlib import Path

from anim.errors import SceneError
from raycore.config import RenderConfig

from .output_dir import whole_frame


def frame_path(pattern: str, frame: int) -> str:
    """Replace the run of '#' (the schema allows one) with the frame number,
    zero-padded to the run's width; a negative frame gets its sign in front
    of the padded digits (frame -1 in f_###.exr: f_-001.exr)."""
    runs = re.findall(r"#+", pattern)
    if not runs:
        return pattern
    width = len(runs[-1])
    head, _, tail = pattern.rpartition(runs[-1])
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


def plan_frames(scene, out_dir, frames, resume, overwrite, cfg=None, warn=None):
    """(frame, path) pairs to render. With --resume, a frame is skipped only
    if its file is a whole frame of this render (cfg's size and channels):
    a truncated or foreign file is rendered again, said through `warn`.
    Without --resume or --overwrite an existing frame is an error."""
    todo = []
    pattern = scene.spec.output.path
    if "#" not in pattern and len(frames) > 1:
        raise SceneError(scene.path, "output.path", "needs a run of '#' for the frame number when rendering several frames")
    for f in frames:
        path = frame_file(scene, out_dir, f)
        if path.exists() and not overwrite:
            if not resume:
                raise SceneError(path, "", "frame exists; use --resume to skip finished frames or --overwrite to replace them")
            problem = whole_frame(path, cfg.width, cfg.height, frame_channels(cfg)) if cfg else ""
            if not problem:
                continue
            if warn:
                warn(f"{path}: {problem}; rendering frame {f} again")
        todo.append((f, path))
    return todo
