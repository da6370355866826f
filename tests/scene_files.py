"""Small scene files for tests: the demo's meshes and a scene of the objects given."""
import shutil

from conftest import ROOT

DEMO = ROOT / "anim" / "builtin" / "demo"


def scene_with(tmp_path, objects_yaml, camera_yaml="camera: {eye: [0, 1, 6], look_at: [0, 0.5, 0], fov: 40}",
               extra=""):
    for f in ("ball.obj", "floor.obj", "checker.png", "tube_000.obj", "tube_001.obj"):
        shutil.copy(DEMO / f, tmp_path / f)
    text = f"""version: 1
frames: {{start: 0, end: 3, fps: 2}}
output: {{path: out/f_##.exr, resolution: [40, 32]}}
{camera_yaml}
lights: [{{type: point, position: [3, 5, 4], intensity: 30}}]
{extra}
objects:
{objects_yaml}
"""
    path = tmp_path / "s.yaml"
    path.write_text(text)
    return path
