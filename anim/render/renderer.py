"""Frames of one scene at given times: anim (vertices at t) -> raycore
(build, trace, shadow, shade), with work buffers reused across frames;
compile time measured apart by a warm-up; the work memory a render needs,
checked before it starts."""
import time

from anim.errors import SceneError
from anim.scene import AnimatedScene
from raycore.config import SHADOW_ACCEL, RenderConfig
from raycore.camera import camera_basis
from raycore.frame import CameraPose, FrameBuffers, Geometry, Shading, build_structures, render_frame
from raycore.half_float import to_half
from raycore.mesh import vertex_face_csr
from raycore.scene_grid import SceneGrid


class SceneRenderer:
    """Frames of one scene, rendered with reused work buffers: interpolate
    (timed as interp_ms), then build, trace, shadow and shade."""

    def __init__(self, scene: AnimatedScene, cfg: RenderConfig, shading: Shading, pending_writes: int = 0):
        self.scene, self.cfg, self.shading = scene, cfg, shading
        self.vf = vertex_face_csr(scene.faces, scene.n_vertices)
        # image ring: the frame being written, the one being rendered, and every
        # write in flight (pending_writes: how many frames may still be writing)
        self.buffers = FrameBuffers(cfg.width, cfg.height, shading.lights.shape[0], cfg.packet,
                                    n_images=pending_writes + 2)
        # static objects: gathered, binned and given normals once (raycore/scene_grid.py)
        self.scene_grid = SceneGrid(scene.faces, scene.n_vertices, *self.vf, cfg.grid_density,
                                    scene.moving_triangles, scene.moving_object_ranges)

    def render(self, t):
        """(interp_ms, FrameResult) of the frame at time t."""
        scene = self.scene
        t0 = time.perf_counter()
        vertices = scene.vertices_at(t)
        pose = CameraPose(*scene.camera_at(t))
        interp_ms = (time.perf_counter() - t0) * 1e3
        geom = Geometry(vertices, scene.faces, scene.tri_material, scene.uvs, *self.vf)
        motion = self.shutter(t)
        result = render_frame(geom, self.shading, pose, self.cfg, self.buffers, self.scene_grid, motion=motion)
        return interp_ms + (motion.interp_ms if motion else 0.0), result

    def shutter(self, t):
        """The frame's motion within its shutter (None without motion blur,
        or when nothing in the scene moves: no object, no camera)."""
        cfg = self.cfg
        if cfg.shutter <= 0 or (not self.scene.moving and self.scene.spec.camera.keys is None):
            return None
        return Shutter(self.scene, t, cfg.shutter / self.scene.spec.frames.fps, cfg.shutter_position)

    def trace_camera_only(self, t, shadow_structure=True):
        """Interpolate, build the structures (the camera rays' and, with
        shadow_structure, the shadow rays') and trace the camera rays, and
        nothing more: what warm_up compiles here while a helper compiles the rest."""
        vertices = self.scene.vertices_at(t)
        geom = Geometry(vertices, self.scene.faces, self.scene.tri_material, self.scene.uvs, *self.vf)
        names = {self.cfg.accel}
        if shadow_structure and self.cfg.shadows and self.shading.lights.shape[0] > 0:
            names.add(self.cfg.shadow_accel or SHADOW_ACCEL)
        _, built = build_structures(names, geom, self.cfg, self.scene_grid, self.buffers, {})
        pose = CameraPose(*self.scene.camera_at(t))
        cam = camera_basis(pose.eye, pose.look_at, pose.up, pose.fov, self.cfg.width, self.cfg.height)
        built[self.cfg.accel].trace_camera(cam, self.cfg.width, self.cfg.height, (0.5, 0.5))


class Shutter:
    """u in [0, 1] across the shutter -> (vertices, CameraPose) at that
    time: the shutter is open for `length` seconds, centred on the frame
    time t, opening at it (start), or closing at it (end). Interpolation
    time is summed in interp_ms."""
    OPENS = {"center": -0.5, "start": 0.0, "end": -1.0}

    def __init__(self, scene, t, length, position):
        self.scene, self.interp_ms = scene, 0.0
        self.t, self.opens, self.length = t, self.OPENS[position], length
        # objects that cannot move within the shutter stay where the frame
        # time put them (it lies in the shutter): not placed again per pass
        t_open, t_close = self.time_of(0.0), self.time_of(1.0)
        self.held = {o for o in scene.one_by_one if o.held_over(t_open, t_close)}

    def time_of(self, u):
        return self.t + (self.opens + u) * self.length     # exactly t at u = 1/2 when centred

    def __call__(self, u):
        t0 = time.perf_counter()
        t = self.time_of(u)
        out = self.scene.vertices_at(t, self.held), CameraPose(*self.scene.camera_at(t))
        self.interp_ms += (time.perf_counter() - t0) * 1e3
        return out


def warm_up(scene, shading, cfg, t):
    """Compile (or load from numba's cache) every kernel the frame loop will
    use, on a tiny image with the run's settings: two frames (the second
    takes the per-frame paths the first does not: the BVH's refit, a moved
    grid) and an EXR write (the half-float conversion). Returns (seconds,
    {kernel: s} compiled by a helper process); the seconds are reported as
    compile time. Warming only one 1-spp frame left the write, the refit and
    the error budget to compile inside frames 0 and 1 (write_ms 731,
    shade_ms 945 on a cold run; issue 20).

    On a cold cache a helper process compiles the surface half meanwhile
    (compile_helper.py): this process first compiles the camera half (with
    the structures' builds and the EXR write's half floats, to even the
    halves out), waits for the helper, and then loads its
    kernels (the zip layout among them) from the cache."""
    from . import compile_helper
    t0 = time.perf_counter()
    dt = 1.0 / scene.spec.frames.fps
    small = cfg.__class__(**{**cfg.__dict__, "width": 2 * cfg.packet, "height": 2 * cfg.packet})
    helper = compile_helper.start(scene, small, t)
    renderer = SceneRenderer(scene, small, shading)
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

    from raycore.image_io import write_exr
    with tempfile.TemporaryDirectory() as tmp:
        write_exr(f"{tmp}/warm.exr", channels, {}, compression)


# bytes per pixel of one pass: camera hits (16), the visible-surface rows (96),
# one light's shadow rays and their sort (52), shaded colour (12), the image
# ring (2 x 20), and the EXR write's buffers (52: half copy, the zip encoder's
# three copies of the frame's bytes and its deflated blocks, measured with
# tracemalloc on an incompressible 1024^2 RGBA + Z frame; the OpenEXR
# bindings' codecs took 8)
BYTES_PER_PIXEL = 16 + 96 + 52 + 12 + 40 + 52


# an error budget's group of passes holds about one image's samples twice
# (each pass's surface rows copied, then joined: 2 x 96) and their camera rays (28)
BUDGET_BYTES_PER_PIXEL = 2 * 96 + 28
# bytes per triangle: gathered vertices (36), faces and materials (16), normals
# and their CSR (~24), grid cell lists (~4 cells x 4) and a kd-tree (~64)
BYTES_PER_TRIANGLE = 36 + 16 + 24 + 16 + 64


def available_bytes():
    """MemAvailable of /proc/meminfo (None where there is none)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def check_memory(scene, cfg, available=None):
    """SceneError (exit 2) with the estimate if rendering would not fit in
    the memory available now, instead of an out-of-memory kill mid-run."""
    pixels = cfg.width * cfg.height
    per_pixel = (BYTES_PER_PIXEL + 4 * len(scene.spec.lights)
                 + sum({"N": 24, "P": 24, "id": 8}[a] for a in cfg.aovs)     # AOV + its EXR copy
                 + (BUDGET_BYTES_PER_PIXEL if cfg.max_error > 0 else 0))
    need = pixels * per_pixel + scene.faces.shape[0] * BYTES_PER_TRIANGLE
    available = available_bytes() if available is None else available
    if available is not None and need > 0.9 * available:
        raise SceneError(scene.path, "output.resolution",
                         f"{cfg.width}x{cfg.height} with {scene.faces.shape[0]:,} triangles needs about "
                         f"{_size(need)} of work memory; {_size(available)} are available")
    return need


def _size(n_bytes) -> str:
    return f"{n_bytes / 1024 ** 3:.1f} GiB" if n_bytes >= 1024 ** 3 else f"{n_bytes / 1024 ** 2:.0f} MiB"
