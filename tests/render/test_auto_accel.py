"""render.accel: auto (the default) picks the camera rays' structure by the
scene's triangles per pixel, as measured (anim/render/settings.auto_accel),
says which and why in stats.json and the summary, and an explicit
structure is left as named."""
import json

from click.testing import CliRunner

from anim.render.settings import AUTO_TRIANGLES_PER_PIXEL, AUTO_TRIANGLES_PER_PIXEL_STATIC, auto_accel, config_of
from anim.scene import AnimatedScene
from cli.main import main
from scene_files import scene_with

BALL = "  - {name: ball, mesh: ball.obj}\n  - {name: floor, mesh: floor.obj}\n"


def test_the_rule_follows_the_measured_crossovers():
    pixels = 1024 * 1024
    assert auto_accel(16_000, 16_000, pixels)[0] == "grid"             # hand at 1024^2: 0.016 a pixel
    assert auto_accel(79_000, 79_000, 256 * 256)[0] == "bvh"           # runner at 256^2: 1.2 a pixel
    assert auto_accel(10_000_000, 10_000_000, pixels)[0] == "bvh"
    limit = int(AUTO_TRIANGLES_PER_PIXEL * pixels)
    assert auto_accel(limit, limit, pixels)[0] == "grid" and auto_accel(limit + 2, limit + 2, pixels)[0] == "bvh"
    # mostly static (a forest, a small moving fairy): the grid rebins only the fairy, so it keeps up longer
    n = int(0.65 * 512 * 512)
    assert auto_accel(n, n // 100, 512 * 512)[0] == "grid" and auto_accel(n, n, 512 * 512)[0] == "bvh"
    name, why = auto_accel(3 * pixels, 0, pixels)
    assert name == "bvh" and f"{AUTO_TRIANGLES_PER_PIXEL_STATIC:g}" in why and "mostly static" in why


def test_auto_is_the_default_resolved_per_size_and_recorded(tmp_path):
    path = scene_with(tmp_path, BALL)               # no render.accel: auto
    scene = AnimatedScene(path)
    big, small = config_of(scene, width=1024, height=1024), config_of(scene, width=16, height=16)
    assert big.accel == "grid" and small.accel == "bvh"
    assert big.accel_choice.startswith("auto: grid") and small.accel_choice.startswith("auto: bvh")
    assert config_of(scene, width=16, height=16, accel="grid").accel_choice == ""
    res = CliRunner().invoke(main, ["render", str(path), "-o", str(tmp_path / "o"), "--res", "16x16",
                                    "--frames", "0:0"])
    assert res.exit_code == 0, res.output
    stats = json.loads((tmp_path / "o" / "stats.json").read_text())
    assert stats["accel"] == "bvh" and stats["accel_choice"].startswith("auto: bvh")
    assert stats["runs"][-1]["accel_choice"] == stats["accel_choice"]
    assert "camera rays: auto: bvh" in res.output
    res = CliRunner().invoke(main, ["render", str(path), "-o", str(tmp_path / "g"), "--res", "16x16",
                                    "--frames", "0:0", "--accel", "grid", "-q"])
    stats = json.loads((tmp_path / "g" / "stats.json").read_text())
    assert res.exit_code == 0 and stats["accel"] == "grid" and "accel_choice" not in stats
