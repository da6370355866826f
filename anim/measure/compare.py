"""`frustrace compare`: the same frames through different acceleration
structures — build and trace times, fps, ray/triangle tests, cells or nodes
visited per packet — and how much their images differ."""
import numpy as np

from anim.render.renderer import SceneRenderer

from anim.render.warm_up import warm_up
from anim.render.settings import config_of, shading_of
from anim.render.stats import fps_of, median_ms
from anim.io.usd import USD_SUFFIXES
from anim.scene import AnimatedScene
from raycore.accelerators import packet_of

from anim.measure.bench import warm_up_frames

# the structures of the camera rays; the shadow rays of every row go through
# one structure (the scene's, else the default), so that rows differ in
# their camera rays alone
STRUCTURES = {
    "grid": {"accel": "grid"},
    "grid-nocull": {"accel": "grid", "grid_cull": False},   # no culling, no mailboxes
    "kdtree": {"accel": "kdtree"},
    "bvh": {"accel": "bvh"},
}
# what names a scene among the tokens: a scene file or a USD stage
SCENE_SUFFIXES = (".yaml", ".yml", *USD_SUFFIXES)
# Wald et al. 2006 (Coherent Grid Traversal), Table: ray/triangle tests per frame
PUBLISHED_TESTS = {"grid-nocull": 14.0e6, "grid": 0.9e6, "kdtree": 0.85e6}


def parse_structures(tokens):
    """['grid', 'vs', 'kdtree', 'scene.yaml'] -> (['grid', 'kdtree'], 'scene.yaml' or None)."""
    names, path = [], None
    for tok in tokens:
        if tok == "vs":
            continue
        if tok in STRUCTURES:
            names.append(tok)
        elif path is None and (tok.lower().endswith(SCENE_SUFFIXES) or "/" in tok):
            path = tok
        else:
            raise ValueError(f"unknown structure {tok!r}; known: {', '.join(STRUCTURES)} (and 'vs')")
    if len(names) < 2:
        raise ValueError("name at least two structures, e.g. `grid vs kdtree`")
    return names, path


def compare_size(scene, res):
    """(width, height): the scene's output.resolution, or `res` pixels wide
    with the scene's aspect kept."""
    w, h = scene.spec.output.resolution
    if res is None:
        return w, h
    return res, max(1, round(res * h / w))


def compare(path, names, n_frames, res, threads, label=None, shadow_accel=None, camera=None):
    """{'rows': [...per structure...], 'diff': [...vs the first...],
    'shadow_accel': ...}; the image is `res` pixels wide (None: the scene's
    resolution), the scene named `label` (default: its path). Every row's
    shadow rays go through `shadow_accel` (None: the scene's structure for
    them, else the default). Instances are copied into the frame's
    triangles (render.instancing: flatten): every row then traces its own
    structure, where a two-level world would trace the same BVH in all."""
    scene = AnimatedScene(path, camera, "flatten")
    frames = scene.frame_numbers[:max(1, n_frames)]
    width, height = compare_size(scene, res)
    shading = shading_of(scene)                 # textures read once, for every structure
    rows, images = [], {}
    shadows = shadow_accel or config_of(scene).shadow_structure
    for name in names:
        cfg = config_of(scene, width=width, height=height, threads=threads, aovs=(), shadow_accel=shadows,
                        **STRUCTURES[name])
        warm_up(scene, shading, cfg, scene.time_of(frames[0]))       # a cold cache: two processes
        renderer = SceneRenderer(scene, cfg, shading)
        for frame in warm_up_frames(scene):                           # warm up the frame loop
            renderer.render(scene.time_of(frame))
        timings = []
        for i, frame in enumerate(frames):
            interp_ms, result = renderer.render(scene.time_of(frame))
            c = result.counters
            timings.append({"interp_ms": interp_ms, **result.timings,
                            "primary_tests": c["primary_tests"], "tri_tests": c["tri_tests"],
                            "visits_per_packet": c["primary_visits"] / max(c["primary_packets"], 1)})
            if i == 0:      # kept past later frames, which reuse the renderer's image ring
                images[name] = result._replace(rgba=result.rgba.copy(), z=result.z.copy())
        fps_raycast, fps_full = fps_of(timings)
        rows.append({"structure": name, "triangles": int(scene.faces.shape[0]), "resolution": [width, height],
                     "packet": packet_of(cfg.accel, cfg.packet),
                     "frames": len(frames),
                     **{k: median_ms(timings, k) for k in ("interp_ms", "build_ms", "trace_ms", "shade_ms",
                                                         "shadow_ms", "primary_tests", "tri_tests",
                                                         "visits_per_packet")},
                     "fps_raycast": fps_raycast, "fps_full": fps_full,
                     "published_tests": PUBLISHED_TESTS.get(name)})
    ref = images[names[0]]
    diffs = []
    for name in names[1:]:
        img = images[name]
        hit_a, hit_b = np.isfinite(ref.z), np.isfinite(img.z)
        both = hit_a & hit_b
        rel = np.abs(img.z[both] / ref.z[both] - 1) if both.any() else np.zeros(1)
        diffs.append({"a": names[0], "b": name, "hit_mismatch_pixels": int(np.sum(hit_a != hit_b)),
                      "max_rel_depth_diff": float(rel.max()),
                      "pixels_depth_diff_over_1e-5": int(np.sum(rel > 1e-5)),
                      "max_rgba_diff": float(np.abs(ref.rgba - img.rgba).max()),
                      "pixels_rgba_diff_over_1e-2": int(np.sum(np.abs(ref.rgba - img.rgba).max(axis=-1) > 1e-2))})
    return {"scene": label or str(path), "shadow_accel": shadows, "rows": rows, "diff": diffs}
