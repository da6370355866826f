"""Writes tests/blender/: a rigged character made in Blender, as Blender's own
exporters write it with their default settings, and Blender's own evaluated
mesh at some frames (the reference the tests compare frustrace's depth to).

Run with a Python that has bpy (Blender as a Python module, `pip install
bpy` in a separate environment: it is large and pins its Python version);
the files it writes are committed, so the tests never need bpy:

    python assets/make_blender_character.py tests/blender

The character: a tube of 640 vertices (32 around, 20 rings, along +z), a
three-bone armature bending it (Bezier keys), an animated shape key
bulging its middle, a Principled BSDF material. Exports: glTF binary (one
animation per action, shape keys as sparse accessors: Blender's defaults),
USD (.usdc: UsdSkel skeleton, animation and blend shape; the defaults
but for "Animation", which Blender's USD export leaves off) and FBX
(Blender's defaults: Y up, unit scale applied, the rig's animation baked,
the shape key as a blend shape).
"""
import sys
from pathlib import Path

import bpy
import numpy as np

AROUND, RINGS, LENGTH, RADIUS = 32, 20, 3.0, 0.3
FRAMES = (1, 4, 8, 12, 16, 20, 24)
MATERIAL = {"colour": (0.8, 0.3, 0.2), "roughness": 0.4, "metallic": 0.0}


def build():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 24
    scene.render.fps = 24
    verts, faces = [], []
    for i in range(RINGS):
        z = LENGTH * i / (RINGS - 1)
        for j in range(AROUND):
            a = 2 * np.pi * j / AROUND
            verts.append((RADIUS * np.cos(a), RADIUS * np.sin(a), z))
    for i in range(RINGS - 1):
        for j in range(AROUND):
            p, q = i * AROUND + j, i * AROUND + (j + 1) % AROUND
            faces.append((p, q, q + AROUND, p + AROUND))
    mesh = bpy.data.meshes.new("Cylinder")
    mesh.from_pydata(verts, [], faces)
    mesh.update()
    body = bpy.data.objects.new("Cylinder", mesh)
    scene.collection.objects.link(body)
    # a Principled BSDF material: both exporters write its base colour, roughness, metallic
    skin = bpy.data.materials.new("Skin")
    skin.use_nodes = True
    bsdf = skin.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*MATERIAL["colour"], 1.0)
    bsdf.inputs["Roughness"].default_value = MATERIAL["roughness"]
    bsdf.inputs["Metallic"].default_value = MATERIAL["metallic"]
    mesh.materials.append(skin)

    arm_data = bpy.data.armatures.new("rig")
    rig = bpy.data.objects.new("rig", arm_data)
    scene.collection.objects.link(rig)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    parent = None
    for k in range(3):
        bone = arm_data.edit_bones.new(f"bone{k}")
        bone.head, bone.tail = (0, 0, k * LENGTH / 3), (0, 0, (k + 1) * LENGTH / 3)
        if parent is not None:
            bone.parent, bone.use_connect = parent, True
        parent = bone
    bpy.ops.object.mode_set(mode="OBJECT")

    # skin weights: linear blends across the joints
    for k in range(3):
        group = body.vertex_groups.new(name=f"bone{k}")
        for i, v in enumerate(verts):
            s = v[2] / (LENGTH / 3) - 0.5               # bone k's middle at s = k
            w = max(0.0, 1.0 - abs(s - k))
            if (k == 0 and s < 0) or (k == 2 and s > 2):
                w = 1.0
            if w > 0:
                group.add([i], w, "REPLACE")
    body.parent = rig
    body.modifiers.new("Armature", "ARMATURE").object = rig

    # one shape key bulging the middle rings, keyed 0 -> 1 -> 0.3
    body.shape_key_add(name="Basis")
    bulge = body.shape_key_add(name="Bulge")
    for i, v in enumerate(verts):
        z = v[2]
        f = max(0.0, 1.0 - abs(z - 1.5) / 0.8)
        bulge.data[i].co = (v[0] * (1 + 0.8 * f), v[1] * (1 + 0.8 * f), z)
    for frame, value in ((1, 0.0), (12, 1.0), (24, 0.3)):
        bulge.value = value
        bulge.keyframe_insert("value", frame=frame)

    # the armature bends: bone1 and bone2 about x, Bezier keys
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="POSE")
    for name, angles in (("bone1", (0, 40, -20)), ("bone2", (0, 60, 30))):
        pb = rig.pose.bones[name]
        pb.rotation_mode = "XYZ"
        for frame, deg in zip((1, 12, 24), angles):
            pb.rotation_euler = (np.radians(deg), 0, 0)
            pb.keyframe_insert("rotation_euler", frame=frame)
    bpy.ops.object.mode_set(mode="OBJECT")
    return scene, body


def evaluated(scene, body):
    """Blender's own evaluated mesh, world coordinates (Blender's Z up), at FRAMES;
    and its triangles (loop_triangles of the evaluated mesh)."""
    out = []
    tris = None
    for f in FRAMES:
        scene.frame_set(f)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        ev = body.evaluated_get(depsgraph)
        m = ev.to_mesh()
        mw = np.array(ev.matrix_world)
        co = np.array([v.co for v in m.vertices], np.float64)
        out.append(co @ mw[:3, :3].T + mw[:3, 3])
        if tris is None:
            m.calc_loop_triangles()
            tris = np.array([t.vertices[:] for t in m.loop_triangles], np.int32)
        ev.to_mesh_clear()
    return np.array(out, np.float32), tris


def main(out_dir):
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    scene, body = build()
    bpy.ops.export_scene.gltf(filepath=str(out / "char.glb"))                 # default settings
    # default settings, but for "Animation", which is off by default (a still otherwise)
    bpy.ops.wm.usd_export(filepath=str(out / "char.usdc"), export_animation=True)
    bpy.ops.export_scene.fbx(filepath=str(out / "char.fbx"))                  # default settings
    verts, tris = evaluated(scene, body)
    np.savez_compressed(out / "char_evaluated.npz", frames=np.array(FRAMES), fps=24.0, vertices=verts,
                        triangles=tris, colour=np.array(MATERIAL["colour"]),
                        roughness=MATERIAL["roughness"], metallic=MATERIAL["metallic"])
    print(f"wrote {out}: char.glb, char.usdc, char.fbx, char_evaluated.npz ({len(verts[0])} vertices)")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "tests/blender")
