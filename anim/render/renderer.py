"""Frames of one scene at given times: anim (vertices at t) -> raycore
(build, trace, shadow, shade), with work buffers reused across frames;
compile time measured apart by a warm-up; the work memory a render needs,
checked before it starts."""
import time

from anim.errors import SceneError
from anim.memory import available_bytes, size_text
from anim.scene import AnimatedScene
from raycore.config import RenderConfig
from raycore.geometry.camera import camera_basis
from raycore.frame import CameraPose, FrameBuffers, Geometry, Shading, render_frame
from raycore.geometry.mesh import vertex_face_csr
from raycore.instancing.world import InstancedStructures
from raycore.structures import FrameStructures


class SceneRenderer:
    """Frames of one scene, rendered with reused work buffers: interpolate
    (timed as interp_ms), then build, trace, shadow and shade."""

    def __init__(self, scene: AnimatedScene, cfg: RenderConfig, shading: Shading, pending_writes: int = 0,
                 structures: FrameStructures = None):
        """structures: another renderer's of this scene (their state does
        not depend on the image size: the warm-up's, built for the frames)."""
        self.scene, self.cfg, self.shading = scene, cfg, shading
        self.vf = vertex_face_csr(scene.faces, scene.n_vertices) if structures is None else \
            (structures.vf_start, structures.vf_faces)
        # image ring: the frame being written, the one being rendered, and every
        # write in flight (pending_writes: how many frames may still be writing)
        self.buffers = FrameBuffers(cfg.width, cfg.height, shading.lights.shape[0], cfg.packet,
                                    n_images=pending_writes + 2)
        # static objects: gathered, binned and given normals once (raycore/grid/incremental.py);
        # instances: the prototypes' trees under a top level (raycore/instancing)
        if structures is not None:
            self.structures = structures
        elif scene.two_level:
            self.structures = InstancedStructures(scene.faces, scene.n_vertices, *self.vf, scene.proto_ranges,
                                                  scene.proto_moving, scene.world_ranges)
        else:
            self.structures = FrameStructures(scene.faces, scene.n_vertices, *self.vf, cfg.grid_density,
                                              scene.moving_triangles, scene.moving_object_ranges)

    def geometry(self, t, vertices):
        """The frame's Geometry at time t over these vertices."""
        scene = self.scene
        return Geometry(vertices, scene.faces, scene.tri_material, scene.uvs, *self.vf, scene.instances_at(t))

    def render(self, t):
        """(interp_ms, FrameResult) of the frame at time t."""
        scene = self.scene
        t0 = time.perf_counter()
        geom = self.geometry(t, scene.vertices_at(t))           # an instanced world's instances too
        pose = CameraPose(*scene.camera_at(t))
        interp_ms = (time.perf_counter() - t0) * 1e3
        motion = self.shutter(t)
        result = render_frame(geom, self.shading, pose, self.cfg, self.buffers, self.structures, motion=motion)
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
        geom = self.geometry(t, self.scene.vertices_at(t))
        names = {self.cfg.accel}
        if shadow_structure and self.cfg.shadows and self.shading.lights.shape[0] > 0:
            names.add(self.cfg.shadow_structure)
        _, built = self.structures.build(names, geom, self.cfg, self.buffers, {})
        pose = CameraPose(*self.scene.camera_at(t))
        cam = camera_basis(pose.eye, pose.look_at, pose.up, pose.fov, self.cfg.width, self.cfg.height)
        built[self.cfg.accel].trace_camera(cam, self.cfg.width, self.cfg.height, (0.5, 0.5))


class Shutter:
    """u in [0, 1] across the shutter -> (vertices, CameraPose) at that
    time (and the instances, in an instanced world): the shutter is open for `length` seconds, centred on the frame
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
        if self.scene.two_level:
            out += (self.scene.instances_at(t),)
        self.interp_ms += (time.perf_counter() - t0) * 1e3
        return out


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
        # the size is the scene's unless --res changed it
        key = "output.resolution" if [cfg.width, cfg.height] == list(scene.spec.output.resolution) else "--res"
        raise SceneError(scene.path, key,
                         f"{cfg.width}x{cfg.height} with {scene.faces.shape[0]:,} triangles needs about "
                         f"{size_text(need)} of work memory; {size_text(available)} are available")
    return need
