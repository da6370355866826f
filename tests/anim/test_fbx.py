"""FBX files through ufbx in a process of its own (anim/io/fbx.py): takes
chosen by `animation:`, and malformed files as one line and exit 2, never a
crash of the render (the binding can end its interpreter with a
segmentation fault; that process is the worker's)."""
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cli.main import main

pytest.importorskip("ufbx")
CHAR = Path(__file__).resolve().parents[1] / "blender" / "char.fbx"


def _scene(tmp_path, fbx_name="char.fbx", extra=""):
    path = tmp_path / "s.yaml"
    path.write_text(f"""version: 1
frames: {{start: 0, end: 23, fps: 24}}
output: {{path: out/f_##.exr, resolution: [32, 32]}}
camera: {{eye: [4.0, 1.5, 6.0], look_at: [0.0, 1.5, 0.0], fov: 35}}
lights: [{{position: [4, 1.5, 6], intensity: 40}}]
objects:
  - name: character
    mesh: {fbx_name}
{extra}""")
    return path


def test_takes_are_chosen_by_name_or_index_and_a_wrong_one_is_named(tmp_path):
    from anim.scene import AnimatedScene
    (tmp_path / "char.fbx").write_bytes(CHAR.read_bytes())
    first = AnimatedScene(_scene(tmp_path))
    by_name = AnimatedScene(_scene(tmp_path, extra="    animation: rig|rigAction\n"))
    by_index = AnimatedScene(_scene(tmp_path, extra="    animation: 0\n"))
    t = first.time_of(11)
    assert not first.objects[0].static
    np.testing.assert_array_equal(first.vertices_at(t), by_name.vertices_at(t))
    np.testing.assert_array_equal(first.vertices_at(t), by_index.vertices_at(t))
    assert not np.array_equal(first.vertices_at(first.time_of(0)).copy(), first.vertices_at(t))
    # one take, so `all` and a list of it play it too
    for extra in ("    animation: all\n", "    animation: [rig|rigAction]\n"):
        np.testing.assert_array_equal(first.vertices_at(t), AnimatedScene(_scene(tmp_path, extra=extra)).vertices_at(t))
    for extra, words in (("    animation: walk\n", "no take 'walk'"), ("    animation: 3\n", "no take 3"),
                         ("    animation: [0, run]\n", "no take 'run'")):
        res = CliRunner().invoke(main, ["check", str(_scene(tmp_path, extra=extra))])
        assert res.exit_code == 2 and "objects.0.animation" in res.output and words in res.output, res.output
        assert len(res.output.strip().splitlines()) == 1


@pytest.mark.parametrize("damage", ["truncated", "empty", "text", "flipped"])
def test_a_malformed_fbx_is_one_line_and_exit_2(tmp_path, damage):
    """A file cut in half, empty, not an FBX, or with bytes flipped in its
    middle: check and render end with one line naming the file and exit 2
    (or, for a flip that leaves a readable file, render it), and nothing
    crashes."""
    data = CHAR.read_bytes()
    rng = np.random.default_rng(7)
    if damage == "truncated":
        data = data[:len(data) // 2]
    elif damage == "empty":
        data = b""
    elif damage == "text":
        data = b"; FBX 7.4.0 project file\nnot really\n" * 20
    else:
        buf = bytearray(data)
        for i in rng.integers(len(buf) // 4, len(buf), 200):
            buf[i] ^= 0xFF
        data = bytes(buf)
    (tmp_path / "bad.fbx").write_bytes(data)
    path = _scene(tmp_path, "bad.fbx")
    for command in (["check", str(path)], ["render", str(path), "-o", str(tmp_path / "o"), "--frames", "0:0", "-q"]):
        res = CliRunner().invoke(main, command)
        assert res.exit_code in (0, 2), (command, res.exit_code, res.output)
        if res.exit_code == 2:
            assert "bad.fbx" in res.output and len(res.output.strip().splitlines()) == 1, res.output
    if damage != "flipped":
        assert res.exit_code == 2


def test_an_fbx_materials_texture_is_read_with_its_uvs(tmp_path):
    """Blender's FBX of a plane with a 4x4 checker on its base colour
    (tests/blender/textured.fbx, written by assets/make_blender_textured.py):
    the image is found beside the file, the UVs come per corner (points
    split only at UV seams), and the render shows the checker's two colours;
    a texture named but found nowhere is exit 2."""
    from anim.render.renderer import SceneRenderer
    from anim.render.settings import config_of, shading_of
    from anim.scene import AnimatedScene
    here = CHAR.parent
    for name in ("textured.fbx", "checker.png"):
        (tmp_path / name).write_bytes((here / name).read_bytes())
    path = tmp_path / "s.yaml"
    path.write_text("""version: 1
frames: {start: 0, end: 0, fps: 24}
output: {path: out/f_##.exr, resolution: [32, 32]}
camera: {eye: [0, 3, 0.001], look_at: [0, 0, 0], fov: 40}
lights: [{position: [0, 3, 0], intensity: 20}]
objects:
  - name: plane
    mesh: textured.fbx
""")
    scene = AnimatedScene(path)
    shading = shading_of(scene)
    assert shading.tex_info.tolist() == [[0, 4, 4]]
    assert scene.uvs.min() == 0.0 and scene.uvs.max() == 1.0
    _, result = SceneRenderer(scene, config_of(scene, ambient=0.0), shading).render(0.0)
    rgb = result.rgba[..., :3].astype(np.float64)
    lit = rgb.sum(axis=-1) > 0
    redder, bluer = lit & (rgb[..., 0] > 2 * rgb[..., 2]), lit & (rgb[..., 2] > 2 * rgb[..., 0])
    assert redder.sum() > 50 and bluer.sum() > 50
    (tmp_path / "checker.png").unlink()
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2 and "texture file not found" in res.output and "checker.png" in res.output
