"""The FBX reader's own process: ufbx (the official Python binding of the
ufbx C library) loads and evaluates the file here, and fbx.py asks for what
it needs over a pipe.

The binding is young: a wrapper of a scene element that is freed and asked
for again reads freed memory (an element's `name` read twice through two
short-lived wrappers ends the interpreter with a segmentation fault), and
the cyclic garbage collector has crashed it too. So this process holds
every wrapper it makes for as long as it lives (`_held`), never collects
cycles, and leaves by os._exit; and because a crash here is still
possible on a malformed file, it is a process of its own: its death is one
line and exit 2 for the user, never a core dump of the render.

Protocol: length-prefixed pickles on stdin/stdout. Requests are (op, args);
replies ("ok", value) or ("error", message).
"""
import gc
import os
import pickle
import struct
import sys

import numpy as np

_held = []          # every ufbx object made here, kept alive for the process's life


def hold(x):
    _held.append(x)
    return x


def items(lst):
    """The elements of a ufbx list, each wrapper made once and held."""
    hold(lst)
    return [hold(lst[i]) for i in range(len(lst))]


def vec3s(lst):
    return np.array([[v.x, v.y, v.z] for v in items(lst)], np.float64).reshape(-1, 3)


def matrix(m):
    """A ufbx Matrix (columns c0..c3) as a (3, 4) float64 affine map."""
    cols = [hold(getattr(m, c)) for c in ("c0", "c1", "c2", "c3")]
    return np.array([[c.x, c.y, c.z] for c in cols], np.float64).T


def ancestry(node):
    """{element id: name} of a node and its ancestors (whose motion moves it)."""
    ids = {}
    while node is not None:
        ids[int(node.element_id)] = str(node.name)
        node = hold(node.parent)
    return ids


class Reader:
    """One loaded FBX scene: its meshes (an instance each), takes, materials,
    cameras and lights. Cameras and lights are read in frustrace's own
    convention (looking and shining along their -Z, Y up)."""

    def __init__(self, path):
        import ufbx
        self.ufbx = ufbx
        axes = ufbx.axes_right_handed_y_up
        self.scene = hold(ufbx.load_file(path, target_axes=axes, target_unit_meters=1.0, target_camera_axes=axes,
                                         target_light_axes=axes))
        self.takes = items(self.scene.anim_stacks)
        self.parts = []            # (mesh index, instance index) in the order vertices are laid out
        for mi, mesh in enumerate(items(self.scene.meshes)):
            for ni, _ in enumerate(items(mesh.instances)):
                self.parts.append((mi, ni))
        self.cameras = [(ci, ni) for ci, cam in enumerate(items(self.scene.cameras))
                        for ni, _ in enumerate(items(cam.instances))]
        self.light_nodes = [(li, ni) for li, light in enumerate(items(self.scene.lights))
                            for ni, _ in enumerate(items(light.instances))]

    def _animated_nodes(self, take):
        """Element ids of the nodes a take moves."""
        node = int(self.ufbx.ElementType.NODE)
        return sorted({int(hold(p.element).element_id) for layer in items(take.layers)
                       for p in items(layer.anim_props) if int(hold(p.element).type) == node})

    def _drivers(self, mesh, node):
        """{element id: name} of the nodes whose motion moves a mesh instance:
        the node, its skin's bones, and their ancestors."""
        ids = ancestry(node)
        for skin in items(mesh.skin_deformers):
            for cluster in items(skin.clusters):
                bone = hold(cluster.bone_node)
                if bone is not None:
                    ids.update(ancestry(bone))
        return ids

    def info(self):
        meshes = items(self.scene.meshes)
        parts, materials, slot_of = [], [], {}
        for mi, ni in self.parts:
            mesh = meshes[mi]
            node = items(mesh.instances)[ni]
            index = np.fromiter(items(mesh.vertex_indices), np.int64)
            faces = [(f.index_begin, f.num_indices) for f in items(mesh.faces)]
            rest = vec3s(hold(mesh.vertex_position).values) if hold(mesh.vertex_position).unique_per_vertex \
                else None
            if rest is None or len(rest) != mesh.num_vertices:
                rest = vec3s(mesh.vertices)
            world = matrix(hold(node.geometry_to_world))
            local = [slot_of.setdefault(int(m.typed_id), len(slot_of)) for m in items(mesh.materials)]
            face_material = np.fromiter(items(mesh.face_material), np.int64) if len(hold(mesh.face_material)) \
                else np.full(len(faces), -1, np.int64)
            uv = hold(mesh.vertex_uv)
            uvs = None
            if uv.exists:
                values = np.array([[v.x, v.y] for v in items(uv.values)], np.float64).reshape(-1, 2)
                uvs = values[np.fromiter(items(uv.indices), np.int64)]          # per corner
            normal = hold(mesh.vertex_normal)
            normals = None
            if normal.exists and not normal.unique_per_vertex:                 # hard edges possible
                normals = vec3s(normal.values)[np.fromiter(items(normal.indices), np.int64)]
            parts.append({"name": str(node.name), "index": index, "drivers": self._drivers(mesh, node), "faces": np.array(faces, np.int64).reshape(-1, 2),
                          "uv": uvs, "normals": normals,
                          "rest": rest @ world[:, :3].T + world[:, 3],
                          "face_material": np.array([local[k] if 0 <= k < len(local) else -1
                                                     for k in face_material], np.int64)})
        for m in items(self.scene.materials):
            if int(m.typed_id) not in slot_of:
                continue
            pbr = hold(m.pbr)
            colour = hold(hold(pbr.base_color).value_vec4)
            rough = hold(hold(pbr.roughness).value_vec4)
            metal = hold(hold(pbr.metalness).value_vec4)
            texture = hold(hold(pbr.base_color).texture)
            files = None
            if texture is not None:
                content = hold(texture.content)
                files = {"relative": str(texture.relative_filename or ""), "absolute": str(texture.absolute_filename or ""),
                         "content": bytes(content) if content is not None and len(content) else None}
            materials.append({"slot": slot_of[int(m.typed_id)], "name": str(m.name),
                              "colour": (colour.x, colour.y, colour.z), "roughness": rough.x,
                              "metallic": metal.x, "texture": files})
        takes = [{"name": str(t.name), "begin": float(t.time_begin), "end": float(t.time_end),
                  "nodes": self._animated_nodes(t)} for t in self.takes]
        cameras = []
        for ci, ni in self.cameras:
            cam = items(self.scene.cameras)[ci]
            node = items(cam.instances)[ni]
            res = hold(cam.resolution)
            cameras.append({"name": str(node.name), "drivers": ancestry(node),
                            "perspective": int(cam.projection_mode) == int(self.ufbx.ProjectionMode.PERSPECTIVE),
                            "resolution": (float(res.x), float(res.y)) if cam.resolution_is_pixels else None,
                            "aspect": float(cam.aspect_ratio)})
        lights = [{"name": str(items(items(self.scene.lights)[li].instances)[ni].name),
                   "drivers": ancestry(items(items(self.scene.lights)[li].instances)[ni])}
                  for li, ni in self.light_nodes]
        return {"parts": parts, "materials": materials, "takes": takes, "cameras": cameras, "lights": lights,
                "fps": float(hold(self.scene.settings).frames_per_second),
                "creator": str(hold(self.scene.metadata).creator)}

    def _evaluated(self, take, t):
        """The scene at time t of take `take` (the file's rest state for None)."""
        if take is None:
            return self.scene
        anim = hold(self.takes[take].anim)
        return hold(self.ufbx.evaluate_scene(self.scene, anim, float(t), evaluate_skinning=True))

    def camera(self, index, take, times):
        """(node-to-world (3, 4), vertical field of view in degrees) of camera
        `index` at each time of take `take`."""
        ci, ni = self.cameras[index]
        out = []
        for t in times:
            cam = items(self._evaluated(take, t).cameras)[ci]
            node = items(cam.instances)[ni]
            out.append((matrix(hold(node.node_to_world)), float(hold(cam.field_of_view_deg).y)))
        return out

    def lights(self, takes, t):
        """The lights at time t, light i as take takes[i] moves it (None: at
        rest): kind, colour, intensity, decay, world position and direction."""
        ufbx = self.ufbx
        scenes = {k: self._evaluated(k, t) for k in set(takes)}
        out = []
        for (li, ni), take in zip(self.light_nodes, takes):
            light = items(scenes[take].lights)[li]
            node = items(light.instances)[ni]
            colour, local = hold(light.color), hold(light.local_direction)
            m = matrix(hold(node.node_to_world))
            d = m[:, :3] @ np.array([local.x, local.y, local.z])
            out.append({"name": str(node.name), "type": ufbx.LightType(int(light.type)).name.lower(),
                        "decay": ufbx.LightDecay(int(light.decay)).name.lower(),
                        "colour": (float(colour.x), float(colour.y), float(colour.z)),
                        "intensity": float(light.intensity), "position": m[:, 3].tolist(), "direction": d.tolist(),
                        "visible": bool(node.visible)})
        return out

    def evaluate(self, takes, t):
        """World positions of every part at time t, a list: part i as take
        takes[i] moves it (None for a part left at rest)."""
        scenes = {k: self._evaluated(k, t) for k in set(takes) if k is not None}
        out = []
        for (mi, ni), take in zip(self.parts, takes):
            if take is None:
                out.append(None)
                continue
            mesh = items(scenes[take].meshes)[mi]
            node = items(mesh.instances)[ni]
            skinned = hold(mesh.skinned_position)
            pts = vec3s(skinned.values)
            if not skinned.unique_per_vertex or len(pts) != mesh.num_vertices:
                pts = vec3s(mesh.vertices)
            if mesh.skinned_is_local:
                world = matrix(hold(node.geometry_to_world))
                pts = pts @ world[:, :3].T + world[:, 3]
            out.append(pts)
        return out


def _read(stream):
    head = stream.read(8)
    if len(head) < 8:
        return None
    (n,) = struct.unpack("<Q", head)
    return pickle.loads(stream.read(n))


def _write(stream, value):
    data = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(struct.pack("<Q", len(data)) + data)
    stream.flush()


def main():
    gc.disable()
    inp, out = sys.stdin.buffer, sys.stdout.buffer
    reader = None
    while True:
        request = _read(inp)
        if request is None:
            break
        op, args = request
        try:
            if op == "open":
                reader = Reader(*args)
                value = reader.info()
            elif op in ("evaluate", "camera", "lights"):
                value = getattr(reader, op)(*args)
            else:
                raise ValueError(f"unknown request {op!r}")
            _write(out, ("ok", value))
        except Exception as exc:          # ufbx's own errors (a malformed file): one line for the user
            _write(out, ("error", f"{type(exc).__name__}: {exc}"))
    os._exit(0)                           # no interpreter teardown over the held wrappers


if __name__ == "__main__":
    main()
