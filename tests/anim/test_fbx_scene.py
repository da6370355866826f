"""A whole FBX file rendered as a scene (`frustrace render shot.fbx`,
anim/io/fbx_scene.py), against Blender's own evaluation of the shot it
exported (tests/blender/shot.fbx and shot_evaluated.npz, written by
assets/make_blender_shot.py): a skinned, shape-keyed character, a box on
its own action, a static ground, an animated camera, a point light and a
sun. Blender writes one take per object and action that fits it; each
part plays the take that animates it (anim/io/fbx.take_of)."""
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cli.main import main
from raycore.images.image_io import read_exr

pytest.importorskip("ufbx")
HERE = Path(__file__).resolve().parents[1] / "blender"
REF = np.load(HERE / "shot_evaluated.npz")
RES = "80x60"


def _y_up(v):
    """Blender's Z-up coordinates in Y up (x, z, -y), as the FBX is read."""
    v = np.asarray(v, np.float64)
    return np.stack([v[..., 0], v[..., 2], -v[..., 1]], axis=-1)


def _copy(tmp_path):
    for name in ("shot.fbx", "char.fbx"):
        (tmp_path / name).write_bytes((HERE / name).read_bytes())


def _reference(tmp_path):
    """Blender's evaluated meshes (an OBJ keyframe per evaluated frame) seen
    by Blender's camera, as a scene file; Blender's frame f is frame f - 1."""
    keys, cams = [], []
    for f, verts, m, fov in zip(REF["frames"], REF["vertices"], REF["camera"], REF["fov"]):
        obj = tmp_path / f"ref_{f}.obj"
        obj.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in _y_up(verts).astype(np.float32).tolist())
                       + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in REF["triangles"]))
        t = (int(f) - 1) / 24.0
        keys.append(f"      - {{t: {t!r}, mesh: {obj.name}}}\n")
        eye, forward, up = _y_up(m[:3, 3]), _y_up(-m[:3, 2]), _y_up(m[:3, 1])
        cams.append(f"    - {{t: {t!r}, eye: {eye.tolist()}, look_at: {(eye + forward).tolist()}, "
                    f"up: {up.tolist()}, fov: {float(fov)!r}}}\n")
    path = tmp_path / "ref.yaml"
    path.write_text(f"""version: 1
frames: {{start: 0, end: 23, fps: 24}}
output: {{path: ref/f_##.exr, resolution: [320, 240]}}
camera:
  interpolation: linear
  keys:
{''.join(cams)}lights: [{{position: [3, 4, 3], intensity: 20}}]
objects:
  - name: blender
    keyframes:
{''.join(keys)}""")
    return path


def _depths(args, folder):
    res = CliRunner().invoke(main, ["render", *args, "--quiet", "--no-shadows", "--res", RES,
                                    "--frames", f"{REF['frames'][0] - 1}:{REF['frames'][-1] - 1}"])
    assert res.exit_code == 0, res.output
    out = {}
    for f in REF["frames"]:
        (file,) = [p for p in folder.glob("*.exr") if p.stem.rsplit("_", 1)[1].lstrip("0") == str(f - 1).lstrip("0")]
        names, pix, _ = read_exr(str(file))
        out[int(f)] = pix[..., names.index("Z")]
    return out


def test_a_blender_shot_renders_with_the_depth_of_blenders_own_evaluation(tmp_path):
    """Every part moves as Blender moved it (the rig's take for the
    character, the box's for the box, the ground still) and the camera is
    Blender's, frame for frame: depth equal on >= 99.9 % of pixels."""
    _copy(tmp_path)
    got = _depths([str(tmp_path / "shot.fbx"), "-o", str(tmp_path / "fbx")], tmp_path / "fbx")
    ref = _reference(tmp_path)
    want = _depths([str(ref)], tmp_path / "ref")
    for f in got:
        a, b = got[f], want[f]
        both = np.isfinite(a) & np.isfinite(b)
        close = np.abs(np.where(both, a, 0) - np.where(both, b, 0)) <= 1e-4 * np.abs(np.where(both, b, 1))
        same = (np.isinf(a) & np.isinf(b)) | (both & close)
        assert np.isfinite(b).mean() > 0.3
        assert same.mean() >= 0.999, (f, same.mean())


def test_the_shots_camera_lights_frames_and_takes_come_from_the_file(tmp_path):
    from anim.scene import read_scene_file
    _copy(tmp_path)
    notes = []
    spec = read_scene_file(tmp_path / "shot.fbx", notes=notes)
    assert (spec.frames.start, spec.frames.end, spec.frames.fps) == (0, 23, 24.0)
    assert list(spec.output.resolution) == [int(r) for r in REF["resolution"]]
    assert len(spec.camera.keys) == 24
    key = spec.camera.keys[0]
    m = REF["camera"][0]
    np.testing.assert_allclose(key.eye, _y_up(m[:3, 3]), atol=1e-5)
    np.testing.assert_allclose(np.subtract(key.look_at, key.eye), _y_up(-m[:3, 2]), atol=1e-5)
    assert key.fov == pytest.approx(float(REF["fov"][0]), rel=1e-5)
    point, sun = spec.lights
    lamp, sun_m = REF["lights"][0]
    np.testing.assert_allclose(point.position, _y_up(lamp[:3, 3]), atol=1e-5)
    np.testing.assert_allclose(point.color, REF["light_colour"][0], rtol=1e-6)
    # Blender's watts and W/m² under its albedo/pi BRDF, in frustrace's units
    assert point.intensity == pytest.approx(REF["light_energy"][0] / (4 * math.pi ** 2), rel=1e-5)
    assert sun.intensity == pytest.approx(REF["light_energy"][1] / math.pi, rel=1e-5)
    np.testing.assert_allclose(sun.direction, _y_up(-sun_m[:3, 2]), atol=1e-5)
    assert spec.objects[0].animation == "all"
    assert any("camera 'Camera'" in n and "animated" in n for n in notes)


def test_each_part_plays_the_take_that_animates_it():
    """take_of: one take moving a part plays; among several, Blender's
    `<object>|<object>Action`, else the first with a note; a list limits
    the choice; a part no take moves stays at rest."""
    from anim.io.fbx import take_of
    takes = [{"name": "Box|CamAction", "nodes": [1]}, {"name": "Box|BoxAction", "nodes": [1]},
             {"name": "rig|Walk", "nodes": [2, 3]}, {"name": "rig|Run", "nodes": [2, 3]}]
    assert take_of({1: "Box"}, takes, range(4)) == (1, None)
    k, note = take_of({5: "Body", 3: "rig"}, takes, range(4))
    assert k == 2 and "rig|Walk" in note and "rig|Run" in note
    assert take_of({5: "Body", 3: "rig"}, takes, [3]) == (3, None)
    assert take_of({9: "Ground"}, takes, range(4)) == (None, None)


def test_a_whole_fbx_without_camera_or_lights_gets_a_default_view_and_a_light(tmp_path):
    _copy(tmp_path)
    res = CliRunner().invoke(main, ["check", str(tmp_path / "char.fbx")])
    assert res.exit_code == 0, res.output
    assert "no camera in the file" in res.output and "no lights in the file" in res.output
    res = CliRunner().invoke(main, ["render", str(tmp_path / "char.fbx"), "-o", str(tmp_path / "o"), "-q",
                                    "--res", "24x24", "--frames", "0:0"])
    assert res.exit_code == 0, res.output
    names, pix, _ = read_exr(str(next((tmp_path / "o").glob("*.exr"))))
    assert np.isfinite(pix[..., names.index("Z")]).any()


def test_a_missing_camera_a_missing_file_or_a_cut_file_is_one_line_and_exit_2(tmp_path):
    _copy(tmp_path)
    (tmp_path / "cut.fbx").write_bytes((HERE / "shot.fbx").read_bytes()[:60000])
    for args, words in (([str(tmp_path / "shot.fbx"), "--camera", "Nope"], "no camera 'Nope'"),
                        ([str(tmp_path / "none.fbx")], "not found"),
                        ([str(tmp_path / "cut.fbx")], "FBX")):
        for command in ("check", "render"):
            res = CliRunner().invoke(main, [command, *args])
            assert res.exit_code == 2 and words in res.output, res.output
            assert len(res.output.strip().splitlines()) == 1


def test_a_whole_file_is_read_once(tmp_path, monkeypatch):
    """The scene's camera and lights and its meshes come from one worker
    process, which reads the file once (anim/io/fbx.open_fbx)."""
    import subprocess
    from anim.scene import AnimatedScene
    _copy(tmp_path)
    started = []
    real = subprocess.Popen
    monkeypatch.setattr(subprocess, "Popen", lambda *a, **k: started.append(a[0]) or real(*a, **k))
    scene = AnimatedScene(tmp_path / "shot.fbx")
    assert sum("anim.io.fbx_worker" in c for c in started) == 1
    assert np.isfinite(scene.vertices_at(scene.time_of(5))).all()
