"""Writes tests/blender/textured.fbx and checker.png: a plane with a 4x4
checker image texture on its Principled BSDF base colour, as Blender's FBX
exporter writes it with default settings (the image referenced, not embedded).
Run with a Python that has bpy (see make_blender_character.py):

    python assets/make_blender_textured.py tests/blender
"""
import sys

import bpy
from pathlib import Path

out = Path(sys.argv[1]); out.mkdir(parents=True, exist_ok=True)
bpy.ops.wm.read_factory_settings(use_empty=True)
img = bpy.data.images.new("checker", 4, 4)
px = []
for y in range(4):
    for x in range(4):
        c = 1.0 if (x + y) % 2 else 0.0
        px += [c, 0.2, 1 - c, 1.0]
img.pixels = px
img.filepath_raw = str(out / "checker.png"); img.file_format = "PNG"; img.save()
bpy.ops.mesh.primitive_plane_add(size=2)
plane = bpy.context.active_object
mat = bpy.data.materials.new("Checker"); mat.use_nodes = True
bsdf = mat.node_tree.nodes["Principled BSDF"]
tex = mat.node_tree.nodes.new("ShaderNodeTexImage"); tex.image = img
mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
plane.data.materials.append(mat)
bpy.ops.export_scene.fbx(filepath=str(out / "textured.fbx"))
print("ok")
