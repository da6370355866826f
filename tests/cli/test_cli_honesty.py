"""What the commands report is what they did: the kd-tree's packet size,
compare's scene name and image size, the demo found from the package."""
import json

import pytest

from click.testing import CliRunner

from cli.main import main
from scene_files import scene_with

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
    assert result["shadow_accel"] == "bvh"                     # the default, for both rows
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


def _bench_rows():
    base = {"accel": "grid", "shadow_accel": "bvh", "triangles": 117330, "resolution": 1024, "packet": 8,
            "threads": 2, "interp_ms": 10.41, "build_ms": 113.5, "trace_ms": 120.1, "shade_ms": 137.7,
            "shadow_ms": 142.7, "write_ms": 162.2, "fps_raycast": 1114.1, "fps_full": 8.6, "mrays_per_s": 52.1,
            "shadow_mrays_per_s": 10.2, "tri_tests": 3.4e6, "vs_best_peer": 10.72}
    return [{**base, "scene": "demo"}, {**base, "scene": "marbles", "accel": "kdtree"},
            {**base, "scene": "marbles", "accel": "mitsuba", "peer": True, "packet": 0}]


@pytest.mark.parametrize("width", [80, 100, 140, 220])
def test_tables_fit_narrow_terminals_without_cutting_a_cell(width):
    """Issue 20: at 100 columns bench's cells read "de…", "g…", "0.…"; at 80
    compare's "506…", "kdt…". Cells are never cut: low-value columns are left
    out (and named) until the table fits."""
    from rich.console import Console

    from cli.report import bench_table, compare_table
    console = Console(width=width, record=True)
    bench_table(_bench_rows(), console=console)
    row = {"structure": "kdtree", "packet": 8, "build_ms": 50612.25, "trace_ms": 1234.5, "shadow_ms": 98.7,
           "fps_raycast": 506.1, "fps_full": 12.3, "primary_tests": 1.5e6, "tri_tests": 9.9e6,
           "visits_per_packet": 12.5, "published_tests": 3.3e6, "triangles": 1000, "resolution": [64, 64],
           "frames": 2}
    compare_table({"scene": "hand.yaml", "rows": [row, {**row, "structure": "grid"}], "diff": []}, console=console)
    text = console.export_text()
    assert "…" not in text
    for cell in ("demo", "marbles", "kdtree", "mitsuba", "120.1", "8.6", "10.72x", "50612.25", "506.1", "grid"):
        assert cell in text, (cell, text)
    table_lines = [line for line in text.splitlines() if line.startswith(("┃", "│", "┏", "└"))]
    assert max(len(line) for line in table_lines) <= width


def test_bench_and_compare_say_what_they_did(tmp_path):
    """Issue 20: `bench --scene ,` printed an empty table and exit 0; bench
    took only built-in scenes; compare --frames 2 on a one-frame scene timed
    one silently; bench --help spoke only of interpolation error."""
    res = CliRunner().invoke(main, ["bench", "--scene", ","], prog_name="frustrace")
    assert res.exit_code == 2 and "no scene given" in res.output
    res = CliRunner().invoke(main, ["bench", "--scene", str(tmp_path / "nope.yaml")], prog_name="frustrace")
    assert res.exit_code == 2 and "not a file" in res.output
    one = scene_with(tmp_path, "  - {name: ball, mesh: ball.obj}\n")
    one.write_text(one.read_text().replace("frames: {start: 0, end: 3, fps: 2}", "frames: {start: 0, end: 0, fps: 2}"))
    out = tmp_path / "b.json"
    res = CliRunner().invoke(main, ["bench", "--scene", str(one), "--res", "32", "--frames", "1", "--packet", "8",
                                    "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert [r["scene"] for r in json.loads(out.read_text())] == [one.name]
    res = CliRunner().invoke(main, ["compare", "grid", "vs", "bvh", str(one), "--frames", "2", "--res", "32"])
    assert res.exit_code == 0 and "the scene has 1 frame: 1 timed" in res.output, res.output
    helptext = " ".join(CliRunner().invoke(main, ["bench", "--help"]).output.split())
    assert all(w in helptext for w in ("image error", "float precision", "minutes", "--quick --scene torus --res 64"))
    res = CliRunner().invoke(main, ["bench", "--error", "--scene", "demo"], prog_name="frustrace")
    assert res.exit_code == 2 and "exact motion" in res.output          # at once, not after the studies


def test_compare_takes_a_usd_stage_and_one_shadow_structure_for_every_row(tmp_path):
    """compare takes what render takes (a USD stage too), and its rows
    differ in their camera rays alone: every row's shadow rays go through
    the default structure (or --shadow-accel's), and the table says so."""
    pytest.importorskip("pxr")
    from usd_files import shot
    stage = tmp_path / "shot.usda"
    shot(stage)
    out = tmp_path / "c.json"
    res = run("compare", "grid", "vs", "bvh", stage, "--frames", "1", "--res", "32", "--shadow-accel", "grid",
              "--json", out)
    assert res.exit_code == 0, res.output
    result = json.loads(out.read_text())
    assert result["shadow_accel"] == "grid" and "shadow rays of every row through the grid" in res.output
    assert [r["structure"] for r in result["rows"]] == ["grid", "bvh"]
    assert "bvh" in run("compare", "--help").output


def test_a_narrow_bench_table_keeps_what_tells_its_rows_apart():
    """At 80 columns bench left out packet, so the three packet sizes of one
    scene read as three identical rows; the columns that say what a row is
    stay while they tell rows apart, and the BVH's figures print once a scene."""
    from rich.console import Console

    from cli.report import bench_table
    base = _bench_rows()[0]
    bvh = {"bvh_build_ms": 3.6, "bvh_build_ms_per_100k": 22.0, "bvh_refit_ms": 0.1, "moving_triangles": 16880,
           "bvh_refit_ms_per_100k": 0.7, "bvh_rebuilds": 0, "bvh_max_sah_growth": 1.01}
    rows = [{**base, **bvh, "packet": p, "fps_raycast": 100.0 + p} for p in (8, 16, 32)]
    console = Console(width=80, record=True)
    bench_table(rows, console=console)
    text = console.export_text()
    body = [line for line in text.splitlines() if line.startswith("│")]
    assert len(body) == 3 and len(set(body)) == 3, text
    assert all(p in " ".join(body) for p in ("8", "16", "32 *"))
    assert text.count("BVH build") == 1
