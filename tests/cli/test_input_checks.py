"""Mistakes in a scene file that used to pass silently, or pass `check` and
then fail `render`: each is exit 2 with one line naming the key, from `check`
and `render` alike, or a warning where the scene is still meaningful."""
import numpy as np
import pytest
from click.testing import CliRunner

from cli.main import main
from anim.render.frame_files import frame_path
from scene_files import scene_with

BALL = "  - {name: ball, mesh: ball.obj}\n"


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def assert_rejected(path, key, words, tmp_path):
    """check and render both exit 2 with one line naming the key; no frame written."""
    for args in (["check", path], ["render", path, "-o", tmp_path / "out", "-q"]):
        res = run(*args)
        assert res.exit_code == 2, (args[0], res.output)
        lines = res.output.strip().splitlines()
        assert len(lines) == 1 and key in lines[0] and all(w in lines[0] for w in words), res.output
    assert not list((tmp_path / "out").glob("*.exr")) if (tmp_path / "out").exists() else True


@pytest.mark.parametrize("camera, key, words", [
    ("camera: {eye: [1, 2, 3], look_at: [1, 2, 3]}", "camera.look_at", ["equals eye"]),
    ("camera: {eye: [0, 5, 0], look_at: [0, 0, 0], up: [0, 1, 0]}", "camera.up", ["parallel"]),
    ("camera: {eye: [0, 1, 6], look_at: [0, 0, 0], up: [0, 0, 0]}", "camera.up", ["zero"]),
    # animated: degenerate only between the keys (frame 1 of 0..3, t = 0.5)
    ("camera: {keys: [{t: 0, eye: [0, 1, 6], look_at: [0, 0, 0]}, {t: 1, eye: [0, 1, -6], look_at: [0, 0, 0]}],"
     " interpolation: linear}", "camera.keys", ["frame 1", "parallel"]),
    ("camera: {eye: [0, 1, 6], look_at: [0, 0, 0], keys: [{t: 0, eye: [0, 1, 6], look_at: [0, 0, 0]}]}",
     "camera", ["both keys and eye, look_at"]),
])
def test_degenerate_and_contradictory_cameras(tmp_path, camera, key, words):
    assert_rejected(scene_with(tmp_path, BALL, camera_yaml=camera), key, words, tmp_path)


def test_render_checks_the_camera_at_frames_outside_the_files_range(tmp_path):
    camera = ("camera: {keys: [{t: 0, eye: [0, 1, 6], look_at: [0, 0, 0]}, {t: 1.5, eye: [0, 1, 6], look_at: [0, 0, 0]},"
              " {t: 3, eye: [0, 6, 0.0], look_at: [0, 0, 0]}], interpolation: linear}")
    path = scene_with(tmp_path, BALL, camera_yaml=camera)     # frames 0..3 at 2 fps: t <= 1.5
    assert run("check", path).exit_code == 0
    res = run("render", path, "-o", tmp_path / "out", "--frames", "5:6", "-q")
    assert res.exit_code == 2 and "frame 6" in res.output and "camera.keys" in res.output


def test_duplicate_object_names(tmp_path):
    assert_rejected(scene_with(tmp_path, BALL + BALL), "objects.1.name", ["'ball'", "objects.0"], tmp_path)


def test_duplicate_yaml_keys_are_named_with_their_lines(tmp_path):
    path = scene_with(tmp_path, BALL)
    path.write_text(path.read_text().replace("version: 1\n", "version: 1\nversion: 1\n"))
    res = run("check", path)
    assert res.exit_code == 2 and "duplicate key 'version'" in res.output and "line 1" in res.output


@pytest.mark.parametrize("lights, key, words", [
    ("lights: [{type: directional, direction: [0, 0, 0]}]", "lights.0", ["points nowhere"]),
    ("lights: [{type: point, position: [0, .inf, 0]}]", "lights.0.position", ["finite"]),
    ("lights: [{type: point, position: [0, 3, 0], intensity: .nan}]", "lights.0.intensity", ["finite"]),
])
def test_lights_that_point_nowhere_or_sit_at_infinity(tmp_path, lights, key, words):
    path = scene_with(tmp_path, BALL)
    text = path.read_text().replace("lights: [{type: point, position: [3, 5, 4], intensity: 30}]", lights)
    path.write_text(text)
    assert_rejected(path, key, words, tmp_path)


@pytest.mark.parametrize("output, words", [
    ("out/f_##.png", [".exr"]),
    ("out/f_##_v##.exr", ["one run of '#'"]),
    ("out/still.exr", ["needs a run of '#'"]),           # frames 0..3 would share one file
])
def test_output_paths_that_render_would_reject_or_get_wrong(tmp_path, output, words):
    path = scene_with(tmp_path, BALL)
    path.write_text(path.read_text().replace("path: out/f_##.exr", f"path: {output}"))
    assert_rejected(path, "output", words, tmp_path)


def test_a_texture_that_is_not_an_image_fails_check_too(tmp_path):
    path = scene_with(tmp_path, "  - {name: ball, mesh: ball.obj, material: m}\n",
                      extra="materials: {m: {texture: notes.png}}")
    (tmp_path / "notes.png").write_text("not an image")
    assert_rejected(path, "materials.m.texture", ["cannot read texture"], tmp_path)


def test_warnings_for_no_lights_and_frames_past_the_keys(tmp_path):
    camera = "camera: {keys: [{t: 0, eye: [0, 1, 6], look_at: [0, 0, 0]}, {t: 1, eye: [1, 1, 6], look_at: [0, 0, 0]}]}"
    path = scene_with(tmp_path, BALL, camera_yaml=camera)    # frames 0..3 at 2 fps: t up to 1.5
    path.write_text(path.read_text().replace("lights: [{type: point, position: [3, 5, 4], intensity: 30}]", "lights: []"))
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 0, res.output
    assert "no lights" in res.stderr and "camera.keys" in res.stderr and "0..1" in res.stderr
    assert "0 lights, 0 materials, 0 textures" in res.stdout and "1 object " in res.stdout


def test_negative_frame_numbers_keep_their_padding():
    assert frame_path("f_###.exr", -1) == "f_-001.exr"
    assert frame_path("f_###.exr", 7) == "f_007.exr"
    assert frame_path("f_#.exr", -12) == "f_-12.exr"


def test_stl_corners_are_merged_so_normals_are_smooth(tmp_path):
    import numpy as np
    import trimesh
    from anim.io.mesh_io import load_mesh
    sphere = trimesh.creation.icosphere(2)
    sphere.export(tmp_path / "s.stl")                   # 320 triangles, 960 separate corners
    v, f, _ = load_mesh(tmp_path / "s.stl", "scene.yaml", "objects.0.mesh")
    assert len(v) == len(sphere.vertices) and f.shape == sphere.faces.shape
    np.testing.assert_allclose(v[f], sphere.vertices[sphere.faces], atol=1e-6)


@pytest.mark.parametrize("content, words", [
    (None, ["no array 'joints'", "it has: weights"]),
    (b"not a zip at all", ["not an .npz archive"]),
])
def test_weights_files_that_are_not_what_they_should_be(tmp_path, content, words):
    import numpy as np
    path = scene_with(tmp_path, """  - name: arm
    mesh: ball.obj
    skeleton:
      weights: w.npz
      joints: [{name: root}]
""")
    if content is None:
        np.savez(tmp_path / "w.npz", weights=np.ones(10))
    else:
        (tmp_path / "w.npz").write_bytes(content)
    res = run("check", path)
    assert res.exit_code == 2 and "objects.0.skeleton.weights" in res.output, res.output
    assert all(w in res.output for w in words) and "pickle" not in res.output, res.output


def test_output_paths_are_checked_before_any_work(tmp_path):
    path = scene_with(tmp_path, BALL)
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    cases = [
        ["render", path, "-o", blocker / "frames", "-q"],
        ["render", path, "-o", tmp_path / "ok", "--stats", blocker / "stats.json", "-q"],
        ["bench", "--scene", "demo", "--res", "16", "--frames", "1", "--json", blocker / "b.json"],
        ["bench", "--scene", "demo", "--res", "16", "--frames", "1", "--plot", tmp_path / "b.xyz"],
        ["assets", "make", "toys", "-o", tmp_path / "toys", "--preview", tmp_path / "p.xyz"],
    ]
    for args in cases:
        res = run(*args)
        assert res.exit_code == 2, (args, res.output)
        lines = res.output.strip().splitlines()
        assert len(lines) == 1 and "internal error" not in lines[0], (args, res.output)
    assert not (tmp_path / "ok").exists() or not list((tmp_path / "ok").glob("*.exr"))
    assert not (tmp_path / "toys" / "anim.yaml").exists()


def test_assets_make_refuses_to_replace_an_edited_scene(tmp_path):
    out = tmp_path / "hand"
    assert run("assets", "make", "marbles", "-o", out).exit_code == 0
    (out / "anim.yaml").write_text((out / "anim.yaml").read_text() + "# my edit\n")
    res = run("assets", "make", "marbles", "-o", out)
    assert res.exit_code == 2 and "--overwrite" in res.output
    assert (out / "anim.yaml").read_text().endswith("# my edit\n")
    assert run("assets", "make", "marbles", "-o", out, "--overwrite").exit_code == 0
    assert not (out / "anim.yaml").read_text().endswith("# my edit\n")


def test_render_at_another_resolution_and_into_a_closed_pipe(tmp_path):
    import subprocess
    import sys
    from pathlib import Path
    path = scene_with(tmp_path, BALL)
    res = run("render", path, "-o", tmp_path / "out", "--res", "24x18", "--frames", "0:0", "-q")
    assert res.exit_code == 0, res.output
    from raycore.images.image_io import read_exr
    assert read_exr(str(tmp_path / "out" / "f_00.exr"))[1].shape == (18, 24, 5)
    assert run("render", path, "--res", "24by18").exit_code == 2
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.run(f"'{sys.executable}' -m cli.main render '{path}' -o '{tmp_path / 'p'}' --res 24x18 "
                          f"| head -c 1 > /dev/null; echo ${{PIPESTATUS[0]}}",
                          shell=True, executable="/bin/bash", cwd=root, capture_output=True, text=True)
    assert proc.stdout.strip() == "0" and "Error" not in proc.stderr, proc.stderr
    assert len(list((tmp_path / "p").glob("*.exr"))) == 4


def test_paths_leaving_the_scene_directory_warn_and_fail_strict_check(tmp_path):
    import shutil
    scene_dir = tmp_path / "scene"
    scene_dir.mkdir()
    path = scene_with(scene_dir, "  - {name: ball, mesh: ../shared/ball.obj}\n")
    (tmp_path / "shared").mkdir()
    shutil.copy(scene_dir / "ball.obj", tmp_path / "shared" / "ball.obj")
    res = run("check", path)
    assert res.exit_code == 0 and "objects.0.mesh" in res.stderr and "outside" in res.stderr, res.output
    res = run("check", "--strict", path)
    assert res.exit_code == 2 and "objects.0.mesh" in res.output and "--strict" in res.output


@pytest.mark.parametrize("value, ok", [(1e30, True), (1e-30, True), (1e39, False)])
def test_huge_and_tiny_keyed_values(tmp_path, value, ok):
    path = scene_with(tmp_path, f"""  - name: ball
    mesh: ball.obj
    transform: {{translation: {{keys: [[0, 0, 0, 0], [1, {value}, 0, 0]]}}}}
""")
    res = run("render", path, "-o", tmp_path / "out", "--res", "16x12", "-q")
    if ok:
        assert res.exit_code == 0, res.output
    else:
        assert res.exit_code == 2 and "transform.translation.keys" in res.output and "float32" in res.output


def test_a_hundred_thousand_keys_load_and_render(tmp_path):
    """Long key lists are parsed by libyaml (about 3 s per 100,000 keys of
    four numbers; a million take about 35 s) and evaluated by binary search."""
    rows = ", ".join(f"[{i * 1e-5:.5f}, {np.sin(i * 1e-3):.6f}, 0, 0]" for i in range(100_000))
    path = scene_with(tmp_path, f"""  - name: ball
    mesh: ball.obj
    transform: {{translation: {{keys: [{rows}]}}}}
""")
    res = run("render", path, "-o", tmp_path / "out", "--res", "16x12", "-q")
    assert res.exit_code == 0, res.output


def test_a_gltf_accessor_past_its_buffer_is_named(tmp_path):
    from gltf_files import GltfBuilder
    b = GltfBuilder()
    mesh = b.mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), [0, 1, 2])
    b.doc.accessors[0].count = 1000                     # 1000 positions in a 36-byte view
    b.save(tmp_path / "bad.glb", [b.node(mesh=mesh)])
    path = scene_with(tmp_path, "  - {name: g, mesh: bad.glb}\n")
    res = run("check", path)
    assert res.exit_code == 2 and "objects.0.mesh" in res.output and "accessor 0" in res.output, res.output


@pytest.mark.parametrize("joints, words", [
    ("[{name: a, parent: b}, {name: b}]", ["parent 'b' must be a joint listed before"]),
    ("[{name: a, parent: a}]", ["parent 'a' must be a joint listed before"]),     # a cycle of one
    ("[{name: a}, {name: a}]", ["repeats"]),
])
def test_skeletons_with_cycles_or_missing_parents(tmp_path, joints, words):
    path = scene_with(tmp_path, f"""  - name: arm
    mesh: ball.obj
    skeleton: {{weights: w.npz, joints: {joints}}}
""")
    n_vertices = sum(1 for line in (tmp_path / "ball.obj").read_text().splitlines() if line.startswith("v "))
    np.savez(tmp_path / "w.npz", joints=np.zeros(n_vertices, int), weights=np.ones(n_vertices))
    res = run("check", path)
    assert res.exit_code == 2 and "skeleton.joints" in res.output and all(w in res.output for w in words), res.output


def test_all_zero_weights_are_named(tmp_path):
    path = scene_with(tmp_path, """  - name: arm
    mesh: ball.obj
    skeleton: {weights: w.npz, joints: [{name: root}]}
""")
    n_vertices = sum(1 for line in (tmp_path / "ball.obj").read_text().splitlines() if line.startswith("v "))
    np.savez(tmp_path / "w.npz", joints=np.zeros(n_vertices, int), weights=np.zeros(n_vertices))
    res = run("check", path)
    assert res.exit_code == 2 and "has no weight" in res.output, res.output


@pytest.mark.parametrize("suffix", [".gif", ".webp"])
def test_render_preview_animation(tmp_path, suffix):
    from PIL import Image
    camera = "camera: {keys: [{t: 0, eye: [0, 1, 6], look_at: [0, 0, 0]}, {t: 2, eye: [4, 1, 4], look_at: [0, 0, 0]}]}"
    path = scene_with(tmp_path, BALL, camera_yaml=camera)    # frames 0..3 at 2 fps, camera moving
    out = tmp_path / f"anim{suffix}"
    res = run("render", path, "-o", tmp_path / "out", "--res", "32x24", "-q", "--preview", out)
    assert res.exit_code == 0, res.output
    with Image.open(out) as im:
        assert im.n_frames == 4 and im.size == (32, 24)
    assert run("render", path, "-o", tmp_path / "o2", "--preview", tmp_path / "a.mp4").exit_code == 2


def test_a_keyframe_obj_with_an_extra_vertex_line_is_named(tmp_path):
    path = scene_with(tmp_path, """  - name: tube
    keyframes: [{t: 0, mesh: tube_000.obj}, {t: 1, mesh: tube_001.obj}]
""")
    lines = (tmp_path / "tube_001.obj").read_text().splitlines(keepends=True)
    first_v = next(i for i, line in enumerate(lines) if line.startswith("v "))
    lines.insert(first_v + 3, "v 9 9 9\n")         # unreferenced by faces: the loader would drop it
    (tmp_path / "tube_001.obj").write_text("".join(lines))
    res = run("check", path)
    assert res.exit_code == 2 and "keyframes.1.mesh" in res.output and "line by line" in res.output, res.output


def test_a_packet_size_the_kernels_do_not_take_is_named(tmp_path):
    path = scene_with(tmp_path, BALL, extra="render: {packet: 12}")
    res = run("check", path)
    assert res.exit_code == 2 and "render.packet" in res.output and "4, 8, 16, 32" in res.output, res.output


@pytest.mark.parametrize("old, new, key, words", [
    # negative light and reflectance gave negative pixels (issue 20)
    ("intensity: 30}]", "intensity: 30, color: [-1, 1, 1]}]", "lights.0.color.0", ["greater than or equal to 0"]),
    ("objects:", "materials: {m: {diffuse: [-0.8, 0.5, 0.5]}}\nobjects:", "materials.m.diffuse.0", ["greater than or equal to 0"]),
    ("objects:", "render: {background: [-1, 0, 0]}\nobjects:", "render.background.0", ["0"]),
    # no coercion: a bool or a string is not a number (issue 20: samples: true was 1)
    ("{type: point, position: [3, 5, 4],", "{type: area, corner: [0, 3, 0], edge_u: [1, 0, 0], edge_v: [0, 0, 1], "
     "samples: true,", "lights.0.samples", ["valid integer", "not true"]),
    ("{type: point, position: [3, 5, 4],", "{type: area, corner: [0, 3, 0], edge_u: [1, 0, 0], edge_v: [0, 0, 1], "
     "samples: \"16\",", "lights.0.samples", ["valid integer", 'not "16"']),
    ("objects:", "render: {light_probes: true}\nobjects:", "render.light_probes", ["not true"]),
    ("objects:", "render: {shadows: 1}\nobjects:", "render.shadows", ["valid boolean", "not 1"]),
    ("intensity: 30}]", "intensity: \"30\"}]", "lights.0.intensity", ["valid number"]),
    ("frames: {start: 0,", "frames: {start: true,", "frames.start", ["not true"]),
])
def test_negative_colours_and_coerced_types_are_refused(tmp_path, old, new, key, words):
    path = scene_with(tmp_path, BALL)
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))
    assert_rejected(path, key, words, tmp_path)


def test_radiance_past_the_half_float_range_is_warned_and_counted(tmp_path):
    path = scene_with(tmp_path, BALL)
    path.write_text(path.read_text().replace("intensity: 30}]", "intensity: 1e37}]"))
    res = run("render", path, "-o", tmp_path / "out", "--frames", "0:1", "--res", "24x16")
    assert res.exit_code == 0, res.output
    warned = [line for line in res.output.splitlines() if "largest half" in line]
    assert len(warned) == 1 and "+inf" in warned[0] and "frame 0" in warned[0]
    stats = __import__("json").loads((tmp_path / "out" / "stats.json").read_text())
    assert stats["frames"][0]["half_overflow"] > 0
    ok = scene_with(tmp_path, BALL)
    res = run("render", ok, "-o", tmp_path / "ok", "--frames", "0:1", "--res", "24x16")
    assert "largest half" not in res.output
