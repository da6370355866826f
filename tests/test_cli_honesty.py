"""What the commands report is what they did: the kd-tree's packet size,
compare's scene name and image size, the demo found from the package."""
import json

import pytest

from click.testing import CliRunner

from cli.main import main
from test_scene import scene_with

BALL = "  - {name: ball, mesh: ball.obj}\n"


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_kdtree_with_a_packet_size_warns_and_records_8(tmp_path):
    path = scene_with(tmp_path, BALL)
    res = run("render", path, "-o", tmp_path / "out", "--accel", "kdtree", "--packet", "32", "--frames", "0:0", "-q")
    assert res.exit_code == 0 and "kd-tree traces 8x8" in res.stderr, res.output
    stats = json.loads((tmp_path / "out" / "stats.json").read_text())
    assert stats["packet"] == 8 and stats["runs"][-1]["packet"] == 8


def test_compare_names_the_builtin_scene_and_keeps_a_scene_files_size(tmp_path):
    out = tmp_path / "c.json"
    res = run("compare", "grid", "vs", "kdtree", "--scene", "demo", "--res", "48", "--frames", "1", "--json", out)
    assert res.exit_code == 0, res.output
    result = json.loads(out.read_text())
    assert result["scene"] == "demo" and "frustrace-compare" not in res.output
    assert result["rows"][0]["resolution"] == [48, 48]
    path = scene_with(tmp_path, BALL)                     # output.resolution [40, 32]
    res = run("compare", "grid", "vs", "kdtree", path, "--frames", "1", "--json", out)
    assert res.exit_code == 0, res.output
    assert json.loads(out.read_text())["rows"][0]["resolution"] == [40, 32]
    res = run("compare", "grid", "vs", "kdtree", path, "--frames", "1", "--res", "80", "--json", out)
    assert json.loads(out.read_text())["rows"][0]["resolution"] == [80, 64]


def test_the_demo_is_a_builtin_scene_found_in_the_package(tmp_path):
    res = run("assets", "list")
    assert res.exit_code == 0 and "demo" in res.output and "7,330" in res.output
    res = run("assets", "make", "demo", "-o", tmp_path / "demo")
    assert res.exit_code == 0, res.output
    assert run("check", tmp_path / "demo" / "anim.yaml").exit_code == 0


def test_max_error_nan_on_the_command_line_is_refused(tmp_path):
    """NaN passes every range check; in the scene file it is exit 2 already."""
    path = scene_with(tmp_path, BALL)
    res = run("render", path, "-o", tmp_path / "out", "--max-error", "nan", "--frames", "0:0", "-q")
    assert res.exit_code == 2 and "nan" in res.output
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").glob("*.exr"))


@pytest.mark.parametrize("args, words", [
    (["render", "--spp", "x", "scene.yaml"], ["--spp", "'x'", "frustrace render --help"]),
    (["render"], ["Missing argument", "frustrace render --help"]),
    (["bogus"], ["No such command 'bogus'"]),
    (["bench", "--res", "0"], ["--res"]),
])
def test_option_errors_are_one_line_and_exit_2(args, words):
    """Issue 20: click printed Usage, Try, a blank line and Error (four lines)."""
    res = CliRunner().invoke(main, args, prog_name="frustrace")
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("frustrace: error: "), res.output
    assert all(w in lines[0] for w in words), lines[0]
