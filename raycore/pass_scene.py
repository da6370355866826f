"""What one pass of camera rays traces: the frame's structures, vertex
normals and camera, moved to the pass's time and lens position."""
import time

import numpy as np

from raycore.geometry.camera import camera_basis, thin_lens


class PassScene:
    """The structures, vertex normals and camera that a pass traces: built
    once for a frame without motion blur, moved to each pass's time under
    it (rebuilt only when the vertices changed: a frame in which only the
    camera moves, or nothing within the shutter, builds once), and the
    camera put at each pass's lens position under a thin lens."""

    def __init__(self, names, geom, pose, cfg, structures, buffers, counters, timings, motion,
                 camera_accel, shadow_accel):
        self.names, self.geom, self.cfg, self.structures = names, geom, cfg, structures
        self.buffers, self.counters, self.timings, self.motion = buffers, counters, timings, motion
        self.camera_accel, self.fixed_shadow_accel = camera_accel, shadow_accel
        self.key = None                      # (time, lens) of what is built now
        self.built_vertices = None           # the vertices the structures were built over
        self.pose = self.pinhole = None
        self.lazy = False                    # vertex normals made for the seen vertices only (normals_for)
        self.times_seen, self.lens_seen = set(), set()
        if motion is None:                   # else the first pass's move_to builds
            self.build(geom.vertices, pose)

    def build(self, vertices, pose, instances=None):
        """The structures over these vertices (and, in an instanced world,
        these instances: instancing/world.InstanceFrame), when they changed."""
        cfg, t0 = self.cfg, time.perf_counter()
        if instances is not None and instances is not self.geom.instances:
            # a pass at another time: built again when a copy moved (not when only the camera did)
            if not np.array_equal(instances.matrices, self.geom.instances.matrices):
                self.built_vertices = None
            self.geom = self.geom._replace(instances=instances)
        if self.built_vertices is None or not np.array_equal(vertices, self.built_vertices):
            geom = self.geom._replace(vertices=vertices)
            # the frame's corners may be left ungathered (structures.build) when
            # this pass's own structures trace every ray: normals_for gathers the seen ones
            self.tri_verts, built = self.structures.build(
                self.names, geom, self.cfg, self.buffers, self.counters,
                lazy_corners=self.camera_accel is None and self.fixed_shadow_accel is None)
            self.accel = built[cfg.accel] if self.camera_accel is None else self.camera_accel
            self.shadow_accel = (built.get(cfg.shadow_structure) if self.fixed_shadow_accel is None
                                 else self.fixed_shadow_accel)
            self.built_vertices = vertices.copy() if self.motion is not None else vertices
            self.counters["builds"] += 1
            self.timings["build_ms"] += (time.perf_counter() - t0) * 1e3
            t0 = time.perf_counter()
            self.lazy = self.structures.lazy_normals(cfg.width * cfg.height)
            if self.lazy:
                self.structures.forget_normals()
                self.normals = self.structures.normals
            else:
                self.normals = self.structures.normals_now()
            self.timings["shade_ms"] += (time.perf_counter() - t0) * 1e3
        if pose != self.pose:
            self.pose = pose
            self.pinhole = camera_basis(pose.eye, pose.look_at, pose.up, pose.fov, cfg.width, cfg.height)
        self.cam = self.pinhole

    def normals_for(self, prim):
        """The vertex normals the hits prim (triangle ids, -1 misses) need:
        made now for the vertices they see when the frame's are made lazily
        (FrameStructures.lazy_normals), else all made at the build."""
        if self.lazy:
            t0 = time.perf_counter()
            self.structures.normals_for(prim)
            self.timings["shade_ms"] += (time.perf_counter() - t0) * 1e3
        return self.normals

    def move_to(self, sample):
        """Structures and camera of a pass at (time, lens_x, lens_y): time in
        [0, 1] across the shutter (motion(time) gives the vertices and the
        camera pose, and in an instanced world the instances), lens on the
        unit disc."""
        if sample == self.key:
            return
        self.key = sample
        u, lx, ly = sample
        self.counters["passes"] += 1
        self.times_seen.add(u)
        self.lens_seen.add((lx, ly))
        if self.motion is not None:
            self.build(*self.motion(u))
        self.cam = self.pinhole
        if self.cfg.aperture_radius > 0 and (lx != 0.0 or ly != 0.0):
            self.cam = thin_lens(self.pinhole, lx, ly, self.cfg.aperture_radius, focus_of(self.pose, self.cfg))


def focus_of(pose, cfg) -> float:
    """The focus distance along the view axis: the scene's, or the eye's
    distance to the point it looks at."""
    if cfg.focus_distance > 0:
        return cfg.focus_distance
    return float(np.linalg.norm(np.subtract(pose.look_at, pose.eye, dtype=np.float64)))
