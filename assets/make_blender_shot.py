"""Writes tests/blender/shot.fbx: a whole shot made in Blender and exported
with Blender's default FBX settings (one take per object and action), and
shot_evaluated.npz: Blender's own evaluated meshes, camera and lights at
some frames (the reference `frustrace render shot.fbx` is compared to).

Run with a Python that has bpy (see make_blender_character.py):

    python assets/make_blender_shot.py tests/blender

The shot: the character of make_blender_character.py (skinned and
shape-keyed), a box that slides and turns on its own action, a static
ground plane, a camera that dollies and pans on its own action (sensor
fit auto, 36 mm sensor, a 35 mm lens, 320x240), a point light and a sun.
"""
import math
import sys
from pathlib import Path

import bpy
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from make_blender_character import build  # noqa: E402

FRAMES = (1, 6, 12, 18, 24)
RES = (320, 240)


def shot():
    scene, body = build()
    scene.render.resolution_x, scene.render.resolution_y = RES
    scene.render.resolution_percentage = 100
    bpy.ops.mesh.primitive_cube_add(size=0.8, location=(1.6, 0.5, 0.4))
    box = bpy.context.active_object
    box.name = "Box"
    for frame, x, turn in ((1, 1.6, 0), (12, 1.0, 45), (24, 1.3, 120)):
        box.location.x = x
        box.rotation_euler = (0, 0, math.radians(turn))
        box.keyframe_insert("location", frame=frame)
        box.keyframe_insert("rotation_euler", frame=frame)
    bpy.ops.mesh.primitive_plane_add(size=8, location=(0, 0, -0.05))
    bpy.context.active_object.name = "Ground"
    cam_data = bpy.data.cameras.new("Camera")
    cam_data.lens, cam_data.sensor_width = 35.0, 36.0
    cam = bpy.data.objects.new("Camera", cam_data)
    scene.collection.objects.link(cam)
    scene.camera = cam
    for frame, eye, look in ((1, (5.0, -7.0, 2.5), (0.3, 0.0, 1.2)), (24, (3.5, -7.5, 3.0), (0.8, 0.0, 1.0))):
        cam.location = eye
        direction = np.subtract(look, eye)
        cam.rotation_euler = _look_rotation(direction)
        cam.keyframe_insert("location", frame=frame)
        cam.keyframe_insert("rotation_euler", frame=frame)
    point = bpy.data.lights.new("Lamp", "POINT")
    point.energy, point.color = 800.0, (1.0, 0.9, 0.8)
    lamp = bpy.data.objects.new("Lamp", point)
    lamp.location = (3.0, -3.0, 4.0)
    scene.collection.objects.link(lamp)
    sun_data = bpy.data.lights.new("Sun", "SUN")
    sun_data.energy = 2.0
    sun = bpy.data.objects.new("Sun", sun_data)
    sun.rotation_euler = (math.radians(40), math.radians(10), math.radians(30))
    scene.collection.objects.link(sun)
    return scene, [body, box, bpy.data.objects["Ground"]], cam, [lamp, sun]


def _look_rotation(direction):
    """Euler angles turning a Blender camera (looking down its -Z, Y up) along `direction`."""
    from mathutils import Vector
    return Vector(direction).to_track_quat("-Z", "Y").to_euler()


def evaluated(scene, objects, cam, lights):
    """At FRAMES: every object's evaluated world vertices and triangles,
    the camera's world matrix and vertical field of view, the lights' world
    matrices (Blender's Z up)."""
    verts, tris, cams, fovs, lamps = [], None, [], [], []
    aspect = RES[0] / RES[1]
    for f in FRAMES:
        scene.frame_set(f)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        pts, faces, base = [], [], 0
        for ob in objects:
            ev = ob.evaluated_get(depsgraph)
            m = ev.to_mesh()
            mw = np.array(ev.matrix_world)
            co = np.array([v.co for v in m.vertices], np.float64)
            pts.append(co @ mw[:3, :3].T + mw[:3, 3])
            m.calc_loop_triangles()
            faces.append(np.array([t.vertices[:] for t in m.loop_triangles], np.int32) + base)
            base += len(co)
            ev.to_mesh_clear()
        verts.append(np.concatenate(pts))
        tris = np.concatenate(faces) if tris is None else tris
        cams.append(np.array(cam.evaluated_get(depsgraph).matrix_world))
        h = cam.data.angle_x if aspect >= 1 else cam.data.angle_y
        fovs.append(math.degrees(2 * math.atan(math.tan(h / 2) / aspect)) if aspect >= 1 else math.degrees(h))
        lamps.append([np.array(lt.evaluated_get(depsgraph).matrix_world) for lt in lights])
    return (np.array(verts, np.float32), tris, np.array(cams), np.array(fovs), np.array(lamps))


def main(out_dir):
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    scene, objects, cam, lights = shot()
    bpy.ops.export_scene.fbx(filepath=str(out / "shot.fbx"))                  # default settings
    verts, tris, cams, fovs, lamps = evaluated(scene, objects, cam, lights)
    np.savez_compressed(out / "shot_evaluated.npz", frames=np.array(FRAMES), fps=24.0, vertices=verts,
                        triangles=tris, camera=cams, fov=fovs, resolution=np.array(RES), lights=lamps,
                        light_energy=np.array([lt.data.energy for lt in lights]),
                        light_colour=np.array([tuple(lt.data.color) for lt in lights]))
    print(f"wrote {out}: shot.fbx, shot_evaluated.npz ({verts.shape[1]} vertices, {len(tris)} triangles)")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "tests/blender")
