"""`frustrace assets`: list and generate the built-in scenes, and render a
preview PNG of one (frustrace's own EXR, tone-mapped by OpenImageIO)."""
import tempfile
import time
from pathlib import Path

from anim import builtin


def scene_rows():
    """name, triangles, target, description for every built-in scene."""
    rows = []
    for name in builtin.ALL:
        scene = builtin.get(name)
        rows.append({"name": name, "triangles": scene.triangles, "target": scene.target_triangles,
                     "description": scene.description})
    return rows


def make(name: str, out_dir: Path):
    """Write the scene; returns (anim.yaml path, seconds taken)."""
    start = time.perf_counter()
    path = builtin.get(name).write(out_dir)
    return path, time.perf_counter() - start


def render_preview(anim_yaml: Path, png_path: Path, size: int = 320):
    """Render the middle frame at size x size (4 spp) and write it as a PNG."""
    from anim.render.renderer import SceneRenderer
    from anim.render.settings import config_of, shading_of
    from anim.scene import AnimatedScene
    from raycore.images.image_io import exr_to_png, write_exr

    scene = AnimatedScene(anim_yaml)
    frames = scene.frame_numbers
    cfg = config_of(scene, width=size, height=size, spp=4, aovs=())
    _, result = SceneRenderer(scene, cfg, shading_of(scene)).render(scene.time_of(frames[len(frames) // 2]))
    with tempfile.TemporaryDirectory() as tmp:
        exr = str(Path(tmp) / "preview.exr")
        rgba = result.rgba
        write_exr(exr, {"RGBA": rgba}, {})
        png_path.parent.mkdir(parents=True, exist_ok=True)
        exr_to_png(exr, str(png_path))
