"""`render --preview anim.gif`: the rendered frames, tone-mapped (clipped,
sRGB-encoded, as `assets make --preview` does) and scaled down to at most
MAX_SIDE pixels, as one animated GIF or WebP to look at (Pillow)."""
from pathlib import Path

import numpy as np

from raycore.images.image_io import linear_to_srgb, read_exr

MAX_SIDE = 640
FORMATS = (".gif", ".webp")


def write_animation(frame_paths, out_path: Path, fps: float) -> int:
    """Write the frames that exist, in order; returns how many."""
    from PIL import Image
    images = []
    for path in frame_paths:
        if not Path(path).exists():
            continue
        names, pixels, _ = read_exr(str(path))
        rgb = (linear_to_srgb(pixels[:, :, [names.index(c) for c in "RGB"]]) * 255 + 0.5).astype(np.uint8)
        img = Image.fromarray(rgb)
        scale = MAX_SIDE / max(img.size)
        if scale < 1:
            img = img.resize((max(1, round(img.width * scale)), max(1, round(img.height * scale))),
                             Image.Resampling.LANCZOS)
        images.append(img)
    if images:
        tmp = out_path.with_name(f".{out_path.name}.tmp{out_path.suffix}")
        images[0].save(tmp, save_all=True, append_images=images[1:], duration=round(1000 / fps), loop=0,
                       **({"lossless": False, "quality": 85} if out_path.suffix.lower() == ".webp" else {}))
        tmp.replace(out_path)
    return len(images)
