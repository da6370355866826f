"""A cold numba cache filled by two processes at once.

On a first run every kernel is compiled, one after another, on one core,
while the other cores idle. The kernels split into two halves that need
nothing of each other's results to be compiled: the camera half
(interpolation, the structures' builds, the camera rays' traversal, and the
EXR write's half floats, which even the halves out) and the surface half (the
sweep of sweep.py: the visible-surface gather, the shadow rays and
their traversal, shading and the image's pixels, and, where that evens
the halves out, the shadow BVH's refit: refits_the_bvh). So the main
process compiles the camera half while a helper process compiles the
surface half on camera hits and a shadow BVH made up with the right
types (`MadeUpHits`, `made_up_bvh`: nothing is built there); each writes its
kernels to numba's on-disk cache, and the main process's full warm-up then
loads the helper's kernels instead of compiling them.

Nothing changes the pictures: the helper only fills the cache, and its
output is discarded. The helper is started only when the cache lacks the
surface half (a warm run costs nothing), on a machine with more than one
core, and unless FRUSTRACE_COMPILE_HELPER=0.
"""
import os
import pickle
import signal
import subprocess
import sys

import numpy as np

from raycore.jit.counters import Counters
from raycore.frame import sweeps_in_one
from raycore.grid.trace import Hits, row_major_offsets

# the surface half's kernels that tell whether the cache is cold
_PROBES = ("raycore.sweep:shade_blocks",)


def _cached(probe) -> bool:
    """Whether numba's on-disk cache holds a current entry of the kernel."""
    module, name = probe.split(":")
    try:
        dispatcher = getattr(__import__(module, fromlist=[name]), name)
        return bool(dispatcher._cache._cache_file._load_index())
    except Exception:        # numba's cache internals moved: take the cache as warm (no helper)
        return True


def wanted() -> bool:
    """Start a helper: the cache is cold, there is a second core, and it is not switched off."""
    if os.environ.get("FRUSTRACE_COMPILE_HELPER", "1") == "0":
        return False
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return cores > 1 and not all(_cached(p) for p in _PROBES)


# helpers running now (the progress line says so)
running = set()


class Helper:
    """The helper process compiling the surface half; finish() waits for it."""

    def __init__(self, scene, cfg, t):
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])),
               "NUMBA_NUM_THREADS": "1"}
        self.proc = subprocess.Popen([sys.executable, "-m", "anim.render.compile_helper"], env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        self.proc.stdin.write(pickle.dumps((str(scene.path), scene.camera_choice, cfg, t)))
        self.proc.stdin.close()
        self.proc.stdin = None        # communicate() must not flush it again
        running.add(self)

    def finish(self, wait=True) -> dict:
        """{kernel: s} the helper compiled ({} if it failed: the main process
        then compiles what is missing). wait=False ends it at once."""
        if not wait:
            self.proc.kill()
        try:
            out, _ = self.proc.communicate()
        finally:
            running.discard(self)
        if self.proc.returncode != 0:
            return {}
        try:
            return pickle.loads(out)
        except Exception:
            return {}


def refits_the_bvh(cfg, shading) -> bool:
    """Whether the helper, not the main process, compiles the shadow BVH's
    refit: when the frames refit one for their shadow rays and the
    helper's half is the sweep alone (frame.sweeps_in_one with BVH shadows,
    camera rays not through a BVH, no error budget, no area light), and
    the main process's half, the camera rays and the builds, is the longer
    without it. With the phase by phase path's kernels (or an area light's)
    the helper's half is the longer, and the refit stays with the main
    process."""
    lights = shading.lights
    return (cfg.shadows and lights.shape[0] > 0 and cfg.shadow_structure == "bvh"
            and sweeps_in_one(cfg, lights, 1) and cfg.accel != "bvh" and cfg.max_error <= 0
            and not bool((lights[:, 7] > 0).any()))


def start(scene, cfg, t):
    """A Helper compiling the surface half of (scene, cfg) at time t, or None when not wanted."""
    return Helper(scene, cfg, t) if wanted() else None


class MadeUpHits:
    """Camera rays' stand-in in the helper: every ray hits a triangle (ray i
    triangle i mod n) at t = 1, barycentrics (1/3, 1/3), with the types and
    layout the real structures return. Nothing is traced."""
    name = "made-up"

    def __init__(self, n_triangles):
        self.n = n_triangles

    def _hits(self, n):
        prim = (np.arange(n, dtype=np.int32) % self.n) if self.n else np.full(n, -1, np.int32)
        third = np.full(n, 1 / 3, np.float32)
        return Hits(np.ones(n, np.float32), prim, third, third.copy(), Counters(0, 0, 0, 0, 0))

    def trace_camera(self, cam, width, height, jitter):
        return self._hits(width * height), row_major_offsets(width, height)

    def trace_rays(self, origins, dirs, t_min=None, t_max=None, any_hit=False):
        return self._hits(dirs.shape[0])


def made_up_bvh(tri_verts, workspace):
    """The shadow BVH's stand-in in the helper (its build and refit are the
    camera half's): one leaf of the first 8 triangles in a box around
    everything, with the types and layout of a built tree."""
    from raycore.accelerators import BvhAccel
    from raycore.bvh.nodes import CHILD, COUNT, empty_bvh
    k = min(tri_verts.shape[0], 8)
    bvh = empty_bvh(1, k)
    bvh.node[0, :3] = -1e30
    bvh.node[0, 3:6] = 1e30
    bvh.node_i[0, CHILD] = 0
    bvh.node_i[0, COUNT] = k
    bvh.tri[:] = np.arange(k, dtype=np.int32)
    bvh.verts[:] = tri_verts[:k]
    return BvhAccel(bvh, tri_verts, workspace)


def compile_surface_half(scene_path, camera, cfg, t) -> dict:
    """Run two frames of the scene with made-up camera hits, made-up
    vertices (interpolation is the camera half's) and, for BVH shadows, a
    made-up tree (the builds are the camera half's, and so is the EXR
    write's half-float conversion; its zip layout and the shadow BVH's
    refit, on no trees, are this half's). {kernel: s}."""
    from anim.render.compile_watch import watching
    from anim.render.renderer import SceneRenderer
    from anim.render.settings import shading_of
    from anim.scene import AnimatedScene
    from raycore.frame import CameraPose, Geometry, render_frame
    from raycore.bvh.scene import SceneBvh

    scene = AnimatedScene(scene_path, camera)
    shading = shading_of(scene)
    vertices = np.random.default_rng(0).random((scene.n_vertices, 3), dtype=np.float32)
    with watching() as watch:
        renderer = SceneRenderer(scene, cfg, shading)        # its buffers and static geometry
        geom = Geometry(vertices, scene.faces, scene.tri_material, scene.uvs, *renderer.vf)
        camera_hits = MadeUpHits(scene.faces.shape[0])
        shadow_bvh = None
        if cfg.shadow_structure == "bvh":
            tri_verts = np.ascontiguousarray(vertices[scene.faces].reshape(-1, 9))
            shadow_bvh = made_up_bvh(tri_verts, renderer.buffers.work)
            if refits_the_bvh(cfg, shading):
                SceneBvh(scene.faces.shape[0], [], [], scene.faces).refit_moving(tri_verts, vertices)
        pose = CameraPose(*scene.camera_at(t))
        for _ in range(2):        # the second frame takes the per-frame paths
            render_frame(geom, shading, pose, cfg, renderer.buffers, renderer.structures,
                         camera_accel=camera_hits, shadow_accel=shadow_bvh)
        # the zip codec's byte layout (the camera half has the longer compile)
        from raycore.images.exr_zip import CODES, split_blocks
        if scene.spec.output.compression in CODES:
            planar = np.zeros(8, np.uint8)
            split_blocks(planar, np.zeros(1, np.int64), np.full(1, 8, np.int64), 1, CODES["zip"][1],
                         np.empty_like(planar))
    return watch.seconds()


def _main():
    signal.signal(signal.SIGINT, signal.SIG_IGN)     # the main process ends it
    scene_path, camera, cfg, t = pickle.loads(sys.stdin.buffer.read())
    sys.stdout.buffer.write(pickle.dumps(compile_surface_half(scene_path, camera, cfg, t)))
    sys.stdout.flush()
    # the render waits for this process to end: skip the interpreter's
    # teardown (its garbage collection, 0.3-0.4 s; see cli.main.entry)
    os._exit(0)


if __name__ == "__main__":
    _main()
