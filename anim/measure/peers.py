"""`bench --peers`: the same frames through the ray casters that other Python
packages offer, to put frustrace's figures beside theirs.

Every peer gets what frustrace gets: this frame's interpolated vertices (the
interpolation is timed once, the same way), its structure rebuilt or updated
every frame (build_ms), the camera's rays (trace_ms, closest hit) and one
shadow ray per hit and light (shadow_ms, any hit), with all threads it can
use. Left out, in the peers' favour: generating the rays (done in numpy
before the clock starts) and shading (their shade_ms is 0, so their
fps_full is interp + build + trace + shadow).

A peer is used when its package imports (`pip install .[peers]`); tests
never need one. Peers: embreex (Embree 4; its binding traces on the calling
thread, so the rays are split over a thread pool), Open3D's RaycastingScene
(Embree inside, all threads), Mitsuba 3 (llvm_ad_rgb variant: Dr.Jit
vectorizes over rays, all threads).
"""
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from raycore.geometry.camera import camera_basis, pixel_centre_rays

# shadow rays start this fraction of the scene's extent off the surface,
# along the geometric normal turned to the viewer (peers offer no error bounds)
OFFSET_FRACTION = 1e-4


def camera_rays(pose, width, height):
    """Origins (n, 3) and unit directions (n, 3) f32 of the pixel-centre rays,
    row-major, as SPEC section 3 fixes them."""
    o, d = pixel_centre_rays(camera_basis(pose.eye, pose.look_at, pose.up, pose.fov, width, height),
                             width, height)
    return o.astype(np.float32), d.astype(np.float32)


def shadow_rays(points, normals, view, light, extent):
    """Origins, directions, lengths of one light's shadow rays from hit
    points (geometric normals, view directions); only rays to a light in
    front of the surface are returned."""
    n = np.where((np.einsum("ij,ij->i", normals, view) > 0)[:, None], -normals, normals)
    origin = points + n * np.float32(OFFSET_FRACTION * extent)
    if light[0] == 0:
        to = light[1:4][None, :] - origin
        dist = np.linalg.norm(to, axis=1)
        d = to / np.maximum(dist, 1e-30)[:, None]
        length = dist * np.float32(1 - 1e-6)
    else:
        d = np.broadcast_to(-light[1:4], origin.shape)
        length = np.full(len(origin), np.inf, np.float32)
    keep = np.einsum("ij,ij->i", n, d) > 0
    return (np.ascontiguousarray(origin[keep], np.float32), np.ascontiguousarray(d[keep], np.float32),
            np.ascontiguousarray(length[keep], np.float32))


class Embreex:
    name = "embreex"

    def __init__(self, threads):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh
        self._scene_type, self._mesh_type = rtcore_scene.EmbreeScene, TriangleMesh
        self.threads = max(1, threads)
        self.pool = ThreadPoolExecutor(self.threads)

    def _split(self, fn, *arrays):
        """fn over `threads` slices of the rays at once; the results in order."""
        cuts = np.linspace(0, len(arrays[0]), self.threads + 1).astype(int)
        return list(self.pool.map(lambda k: fn(*(a[cuts[k]:cuts[k + 1]] for a in arrays)),
                                  range(self.threads)))

    def build(self, vertices, faces):
        self.scene = self._scene_type()
        self._mesh_type(self.scene, vertices, faces)
        self.scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))   # commit

    def closest(self, o, d):
        parts = self._split(lambda o, d: self.scene.run(o, d, output=1), o, d)
        return (np.concatenate([p["primID"] for p in parts]),
                np.concatenate([p["tfar"] for p in parts]))

    def occluded(self, o, d, length):
        run = lambda o, d, n: self.scene.run(o, d, dists=n, query="OCCLUDED")
        return np.concatenate(self._split(run, o, d, length)) >= 0


class Open3D:
    name = "open3d"

    def __init__(self, threads):
        import open3d as o3d
        self.o3d, self.threads = o3d, threads

    def build(self, vertices, faces):
        t = self.o3d.t.geometry.RaycastingScene(nthreads=self.threads)
        t.add_triangles(self.o3d.core.Tensor(vertices), self.o3d.core.Tensor(faces.astype(np.uint32)))
        t.cast_rays(self.o3d.core.Tensor(np.zeros((1, 6), np.float32)))              # commit
        self.scene = t

    def closest(self, o, d):
        out = self.scene.cast_rays(self.o3d.core.Tensor(np.concatenate([o, d], 1)), nthreads=self.threads)
        prim = out["primitive_ids"].numpy().astype(np.int64)
        prim[prim == np.iinfo(np.uint32).max] = -1
        return prim, out["t_hit"].numpy()

    def occluded(self, o, d, length):
        # tfar is one scalar for all rays: finite lengths go into the directions
        # (t counts in direction lengths), so every ray stops at t = 1
        finite = bool(np.isfinite(length).all())
        rays = np.concatenate([o, d * length[:, None] if finite else d], 1)
        return self.scene.test_occlusions(self.o3d.core.Tensor(rays), tnear=0.0,
                                          tfar=1.0 if finite else float("inf"),
                                          nthreads=self.threads).numpy()


class Mitsuba:
    name = "mitsuba"

    def __init__(self, threads):
        import drjit as dr
        import mitsuba as mi
        mi.set_variant("llvm_ad_rgb")
        if threads:
            dr.set_thread_count(threads)
        self.mi, self.dr, self.scene, self.shape = mi, dr, None, None
        self.instanced = False          # the scene built by build_instanced, not build

    def build(self, vertices, faces):
        mi = self.mi
        if self.scene is None or self.shape != (len(vertices), len(faces)) or self.instanced:
            self.instanced = False
            mesh = mi.Mesh("mesh", len(vertices), len(faces))
            params = mi.traverse(mesh)
            params["vertex_positions"] = mi.Float(vertices.ravel())
            params["faces"] = mi.UInt32(faces.astype(np.uint32).ravel())
            params.update()
            self.scene = mi.load_dict({"type": "scene", "mesh": mesh})
            self.params, self.shape = mi.traverse(self.scene), (len(vertices), len(faces))
        else:                           # an update rebuilds the scene's acceleration structure
            self.params["mesh.vertex_positions"] = mi.Float(vertices.ravel())
            self.params.update()
        self.dr.eval()

    def build_instanced(self, parts):
        """The scene with Mitsuba's own instancing (instanced_parts): the
        other objects' triangles as one mesh, and each instanced object's
        prototype as a shapegroup with an instance per transform. A hit's
        instance (its registry id) and primitive give back the scene's
        triangle id, as the flattened peers' do."""
        mi, dr = self.mi, self.dr
        desc = {"type": "scene"}
        if len(parts["faces"]):
            desc["rest"] = self._mesh("rest", parts["vertices"], parts["faces"])
        for g, (pv, pf, mats, first) in enumerate(parts["groups"]):
            desc[f"group{g}"] = {"type": "shapegroup", "proto": self._mesh(f"proto{g}", pv, pf)}
            for i, m in enumerate(mats):
                desc[f"g{g}_{i}"] = {"type": "instance", "shapegroup": {"type": "ref", "id": f"group{g}"},
                                     "to_world": mi.ScalarTransform4f(np.vstack([m, [0, 0, 0, 1]]).tolist())}
        self.scene, self.shape, self.instanced = mi.load_dict(desc), None, True
        first_id = {}                   # registry id -> the scene's id of its first triangle
        for shape in self.scene.shapes():
            sid = int(np.array(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape)))[0])
            name = shape.id()
            if name == "rest":
                first_id[sid] = -1
            else:
                g, i = (int(x) for x in name[1:].split("_"))
                pv, pf, mats, first = parts["groups"][g]
                first_id[sid] = first + i * len(pf)
        self.lookup = np.full(max(first_id, default=0) + 1, -2, np.int64)
        for sid, first in first_id.items():
            self.lookup[sid] = first
        self.rest_ids = parts["rest_ids"]
        dr.eval()

    def _mesh(self, name, vertices, faces):
        mi = self.mi
        mesh = mi.Mesh(name, len(vertices), len(faces))
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(np.ascontiguousarray(vertices, np.float32).ravel())
        params["faces"] = mi.UInt32(np.ascontiguousarray(faces, np.uint32).ravel())
        params.update()
        return mesh

    def closest(self, o, d):
        pi = self.scene.ray_intersect_preliminary(self._ray(o, d))
        if not self.instanced:
            self.dr.eval(pi.t, pi.prim_index)
            t = np.array(pi.t)
            prim = np.array(pi.prim_index).astype(np.int64)
            prim[~np.isfinite(t)] = -1
            return prim, t
        mi, dr = self.mi, self.dr
        inst, shape = dr.reinterpret_array(mi.UInt32, pi.instance), dr.reinterpret_array(mi.UInt32, pi.shape)
        dr.eval(pi.t, pi.prim_index, inst, shape)
        t = np.array(pi.t)
        local = np.array(pi.prim_index).astype(np.int64)
        inst, shape = np.array(inst).astype(np.int64), np.array(shape).astype(np.int64)
        first = self.lookup[np.where(inst > 0, inst, shape)]
        prim = np.where(first >= 0, first + local, self.rest_ids[np.minimum(local, len(self.rest_ids) - 1)]
                        if len(self.rest_ids) else -1)
        prim[~np.isfinite(t)] = -1
        return prim, t

    def _ray(self, o, d, length=None):
        mi = self.mi
        ray = mi.Ray3f(mi.Point3f(*(mi.Float(o[:, k]) for k in range(3))),
                       mi.Vector3f(*(mi.Float(d[:, k]) for k in range(3))))
        if length is not None:
            ray.maxt = mi.Float(np.minimum(length, 3.4e38))
        return ray

    def occluded(self, o, d, length):
        hit = self.scene.ray_test(self._ray(o, d, length))
        self.dr.eval(hit)
        return np.array(hit)


PEERS = (Embreex, Open3D, Mitsuba)
PEER_NAMES = tuple(p.name for p in PEERS)


def available_peers(threads):
    """The peers whose packages import, set up for `threads` threads."""
    out = []
    for cls in PEERS:
        try:
            out.append(cls(threads))
        except Exception:              # not installed, or no usable backend
            continue
    return out


def instanced_parts(scene, t):
    """A scene's triangles at time t for a peer with instancing of its own,
    or None when no object is instanced: the vertices, the faces of the
    objects that are not instanced and their ids (rest_ids), and per
    instanced object (prototype vertices, prototype faces, (n, 3, 4)
    transforms, the id of its first triangle)."""
    objects = [o for o in scene.objects if o.instances is not None]
    if not objects:
        return None
    keep = np.ones(len(scene.faces), bool)
    groups = []
    for o in objects:
        keep[o.face_offset:o.face_offset + len(o.faces)] = False
        proto = np.empty((len(o.base), 3), np.float32)
        o._place_one(t, proto)
        groups.append((proto, o.proto_faces, o.instances.matrices(t), o.face_offset))
    return {"vertices": scene.vertices_at(t), "faces": scene.faces[keep], "rest_ids": np.flatnonzero(keep),
            "groups": groups}


def peer_frame(peer, vertices, faces, pose, width, height, lights, instanced=None):
    """Timings (ms) and ray counts of one frame through `peer`, and its depth
    per pixel (SPEC Z, +inf on a miss) for the check against frustrace's.
    instanced: instanced_parts(...), for a peer with instancing of its own
    (Mitsuba: shapegroups); the others take the flattened triangles."""
    vertices = np.ascontiguousarray(vertices, np.float32)
    faces = np.ascontiguousarray(faces, np.int32)
    o, d = camera_rays(pose, width, height)
    own = instanced is not None and hasattr(peer, "build_instanced")
    t0 = time.perf_counter()
    if own:
        peer.build_instanced(instanced)
    else:
        peer.build(vertices, faces)
    t1 = time.perf_counter()
    prim, t = peer.closest(o, d)
    t2 = time.perf_counter()
    hit = prim >= 0
    tri = vertices[faces[prim[hit]]]
    geo_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    points = o[hit] + d[hit] * t[hit, None].astype(np.float32)
    geo_n /= np.maximum(np.linalg.norm(geo_n, axis=1, keepdims=True), 1e-30)
    extent = float(np.ptp(vertices, axis=0).max()) if len(vertices) else 1.0
    shadow_ms, n_shadow = 0.0, 0
    for light in lights:
        if not np.any(light[4:7] > 0):
            continue
        so, sd, sl = shadow_rays(points, geo_n, d[hit], light, extent)
        t3 = time.perf_counter()
        peer.occluded(so, sd, sl)
        shadow_ms += (time.perf_counter() - t3) * 1e3
        n_shadow += len(so)
    forward = camera_basis(pose.eye, pose.look_at, pose.up, pose.fov, width, height)[3:6]
    depth = np.where(hit, t * (d @ forward), np.inf).astype(np.float32)
    return {"build_ms": (t1 - t0) * 1e3, "trace_ms": (t2 - t1) * 1e3, "shade_ms": 0.0,
            "shadow_ms": shadow_ms, "shadow_rays": n_shadow}, depth
