"""The warm-up before frame 0: every kernel the frame loop will use
compiled (or loaded from numba's cache) on a tiny image with the run's
settings, so that no frame's timings hold compile time."""
import time

from anim.render import compile_helper
from anim.render.renderer import SceneRenderer
from raycore.images.half_float import to_half


def warm_up(scene, shading, cfg, t, structures=None):
    """Compile (or load from numba's cache) every kernel the frame loop will
    use, on a tiny image with the run's settings: two frames (the second
    takes the per-frame paths the first does not: the BVH's refit, a moved
    grid) and an EXR write (the half-float conversion). Returns (seconds,
    {kernel: s} compiled by a helper process); the seconds are reported as
    the warm-up's, apart from the frames. Warming only one 1-spp frame left
    the write, the refit and the error budget to compile inside frames 0
    and 1. structures: the frames' own (FrameStructures), built here once
    instead of again for the frames (the BVH's trees of a large scene take
    seconds).

    On a cold cache a helper process compiles the surface half meanwhile
    (compile_helper.py): this process first compiles the camera half (with
    the structures' builds and the EXR write's half floats, to even the
    halves out), waits for the helper, and then loads its
    kernels (the zip layout among them) from the cache."""
    t0 = time.perf_counter()
    dt = 1.0 / scene.spec.frames.fps
    small = cfg.__class__(**{**cfg.__dict__, "width": 2 * cfg.packet, "height": 2 * cfg.packet})
    helper = compile_helper.start(scene, small, t)
    renderer = SceneRenderer(scene, small, shading, structures=structures)
    helper_compiled = {}
    if helper is not None:
        done = False
        try:
            # the EXR write's half floats first, which the helper reaches last
            # (the write's zip layout is the helper's: it loads after)
            to_half(renderer.buffers.image()[0])
            renderer.trace_camera_only(t)
            # the shadow BVH's refit is the helper's where that evens the halves out
            renderer.trace_camera_only(t + dt, shadow_structure=not compile_helper.refits_the_bvh(small, shading))
            done = True
        finally:
            helper_compiled = helper.finish(wait=done)
    renderer.render(t)
    _, result = renderer.render(t + dt)
    _write_trial({"RGBA": result.rgba, "Z": result.z, **result.aovs}, scene.spec.output.compression)
    return time.perf_counter() - t0, helper_compiled


def _write_trial(channels, compression):
    """An EXR of these channels into a temporary directory, and gone: what
    compiles (or loads) the write's kernels."""
    import tempfile

    from raycore.images.image_io import write_exr
    with tempfile.TemporaryDirectory() as tmp:
        write_exr(f"{tmp}/warm.exr", channels, {}, compression)
