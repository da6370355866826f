"""A scene file's render settings and shading tables, as raycore takes them."""
import os

import numpy as np

from anim.errors import SceneError
from anim.scene import AnimatedScene
from raycore.config import RenderConfig
from raycore.frame import Shading
from raycore.images.image_io import read_texture


# render.accel: auto, measured on every built-in scene at 128^2-1024^2 and a
# deforming torus of 100K-10M triangles (docs/performance.md, which structure
# for camera rays): the BVH's refit and camera packets cost less than the
# grid's rebuild and walk once triangles outnumber pixels by more than about
# this much; scenes that are mostly static rebin only their moving part in
# the grid, which keeps it ahead up to more triangles a pixel
AUTO_TRIANGLES_PER_PIXEL = 0.2
AUTO_TRIANGLES_PER_PIXEL_STATIC = 1.5
STATIC_SHARE = 0.9                 # "mostly static": at least this share of the triangles never moves


def auto_accel(n_triangles: int, n_moving: int, pixels: int) -> tuple:
    """(structure of the camera rays, why) for render.accel: auto."""
    density = n_triangles / max(pixels, 1)
    static = n_triangles > 0 and n_triangles - n_moving >= STATIC_SHARE * n_triangles
    limit = AUTO_TRIANGLES_PER_PIXEL_STATIC if static else AUTO_TRIANGLES_PER_PIXEL
    name = "bvh" if density > limit else "grid"
    return name, (f"auto: {name} ({n_triangles:,} triangles, {density:.2f} a pixel, "
                  f"{'above' if name == 'bvh' else 'at most'} {limit:g} for a "
                  f"{'mostly static' if static else 'moving'} scene)")


def config_of(scene: AnimatedScene, **overrides) -> RenderConfig:
    """The scene file's render settings, with command-line overrides;
    render.accel: auto resolved to a structure for this scene and size."""
    spec = scene.spec
    base = dict(width=spec.output.resolution[0], height=spec.output.resolution[1],
                packet=spec.render.packet, spp=spec.render.spp, shadows=spec.render.shadows,
                accel=spec.render.accel, shadow_accel=spec.render.shadow_accel or "", grid_density=spec.render.grid_density,
                light_probes=spec.render.light_probes, max_error=spec.render.max_error,
                background=tuple(spec.render.background), ambient=spec.render.ambient,
                aovs=tuple(spec.output.aovs), shutter=spec.render.motion_blur.shutter,
                shutter_position=spec.render.motion_blur.position,
                aperture_radius=spec.camera.aperture_radius, focus_distance=spec.camera.focus_distance or 0.0)
    base.update({k: v for k, v in overrides.items() if v is not None})
    if scene.two_level:
        # one structure serves every ray: the prototypes' trees under a top level
        asked = base["accel"]
        base["accel"], base["shadow_accel"] = "bvh", "bvh"
        base["accel_choice"] = (f"two-level BVH: {len(scene.instance_proto):,} instances of "
                                f"{len(scene.two_level)} prototype(s), {scene.flat_triangles:,} triangles flattened"
                                + (f" (accel {asked} does not trace instances)" if asked not in ("auto", "bvh")
                                   else ""))
    elif base["accel"] == "auto":
        moving = scene.moving_triangles
        n = int(scene.faces.shape[0])
        base["accel"], base["accel_choice"] = auto_accel(n, n if moving is None else len(moving),
                                                         base["width"] * base["height"])
    return RenderConfig(**base)


def render_config(scene: AnimatedScene, *, accel=None, shadow_accel=None, packet=None, threads=0, workers=None,
                  scheduler=None, spp=None, max_error=None, no_shadows=False, res=None, shutter=None,
                  aovs=None) -> tuple:
    """(RenderConfig, warnings) of `frustrace render`: the scene's settings
    with the options given, the render threads set (a local cluster's
    workers share the cores; a remote worker takes all of its machine's),
    and the warnings the combination calls for."""
    from raycore.accelerators import packet_of
    from raycore.jit.presets import set_threads
    warnings = []
    n_threads = set_threads(threads)
    if workers and not threads:
        n_threads = max(1, (os.cpu_count() or 1) // workers)
    elif scheduler and not threads:
        n_threads = 0
    width, height = res if res else (None, None)
    cfg = config_of(scene, packet=int(packet) if packet else None, threads=n_threads, spp=spp, max_error=max_error,
                    shadows=scene.spec.render.shadows and not no_shadows, accel=accel, shadow_accel=shadow_accel,
                    width=width, height=height, shutter=shutter, aovs=aovs)
    if packet and cfg.accel != "grid":
        side = packet_of(cfg.accel, int(packet))
        name = {"kdtree": "kd-tree", "bvh": "BVH"}[cfg.accel]
        warnings.append(f"--packet is for the grid; the {name} traces {side}x{side} packets"
                        + (f" ({cfg.accel_choice})" if cfg.accel_choice else ""))
    if (blur := one_pass_blur_warning(cfg)) is not None:
        warnings.append(blur)
    return cfg, warnings


def one_pass_blur_warning(cfg: RenderConfig):
    """The warning for motion blur or a lens that one pass cannot show, or None."""
    if (cfg.shutter > 0 or cfg.aperture_radius > 0) and cfg.spp == 1 and cfg.max_error == 0:
        return ("motion blur / depth of field with spp 1: the one pass is at the shutter's middle and the "
                "lens centre and shows no blur; raise --spp or render.spp (each pass takes one time and "
                "lens point) or set --max-error")
    return None


def _read_texture_bytes(data: bytes, suffix: str, space: str):
    """A texture stored inside a scene file (a .glb's image): decoded from a
    temporary file, since OpenImageIO reads files."""
    import tempfile
    with tempfile.NamedTemporaryFile(suffix=suffix) as f:
        f.write(data)
        f.flush()
        return read_texture(f.name, space)


def shading_of(scene: AnimatedScene) -> Shading:
    """Materials, lights and textures as flat arrays; textures loaded once."""
    texels, info, offset = [], [], 0
    for path, space, key in zip(scene.texture_paths, scene.texture_spaces, scene.texture_keys):
        try:
            img = read_texture(path, space) if not isinstance(path, tuple) else _read_texture_bytes(*path, space)
        except OSError as exc:
            raise SceneError(scene.path, key, f"cannot read texture: {exc}") from None
        h, w = img.shape[:2]
        texels.append(img.reshape(-1))
        info.append((offset, w, h))
        offset += img.size
    tex_data = np.concatenate(texels) if texels else np.zeros(1, np.float32)
    tex_info = np.asarray(info, np.int64).reshape(-1, 3)
    return Shading(scene.material_table, tex_data, tex_info, scene.light_table)
