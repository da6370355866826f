"""EXR round trip and the command line, through click's test runner."""
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cli.main import main
from raycore.images.image_io import COMPRESSIONS, read_exr, write_exr

DEMO = Path(__file__).resolve().parents[2] / "anim" / "builtin" / "demo"


def test_exr_round_trip_types_and_metadata(tmp_path):
    h, w = 8, 6
    rgba = np.random.default_rng(0).random((h, w, 4)).astype(np.float32)
    z = np.linspace(1, 2, h * w, dtype=np.float32).reshape(h, w)
    z[0, 0] = np.inf
    path = tmp_path / "f.exr"
    write_exr(str(path), {"R": rgba[..., 0], "G": rgba[..., 1], "B": rgba[..., 2], "A": rgba[..., 3],
                          "Z": z, "id": np.full((h, w), 7, np.float32)},
              {"frustrace:frame": 3, "frustrace:time": 0.125, "Software": "frustrace test"})
    names, px, spec = read_exr(str(path))
    assert names == ["R", "G", "B", "A", "Z", "id"]
    assert [str(f) for f in spec.channelformats] == ["half"] * 4 + ["float"] * 2
    assert np.array_equal(px[..., 4], z)                  # float32 kept exactly, inf included
    np.testing.assert_allclose(px[..., :4], rgba, atol=1e-3)
    assert spec.getattribute("frustrace:frame") == 3
    assert abs(spec.getattribute("frustrace:time") - 0.125) < 1e-7
    assert [p.name for p in tmp_path.iterdir()] == ["f.exr"]   # no temp file left


@pytest.fixture
def small_demo(tmp_path):
    scene = tmp_path / "demo"
    shutil.copytree(DEMO, scene)
    text = (scene / "anim.yaml").read_text().replace("resolution: [512, 512]", "resolution: [48, 40], aovs: [N, id]")
    (scene / "anim.yaml").write_text(text)
    return scene / "anim.yaml"


def test_render_writes_frames_and_stats(small_demo, tmp_path):
    out = tmp_path / "frames"
    res = CliRunner().invoke(main, ["render", str(small_demo), "-o", str(out), "--frames", "2:3", "--quiet"])
    assert res.exit_code == 0, res.output
    names, px, spec = read_exr(str(out / "frame_0002.exr"))
    assert names[:5] == ["R", "G", "B", "A", "Z"] and {"N.X", "N.Y", "N.Z", "id"} <= set(names)
    a, z, ids = px[..., 3], px[..., 4], px[..., names.index("id")]
    miss = a == 0
    assert miss.any() and (~miss).any()
    assert np.all(np.isinf(z[miss])) and np.all(ids[miss] == -1) and np.all(ids[~miss] >= 0)
    assert spec.getattribute("frustrace:frame") == 2
    stats = json.loads((out / "stats.json").read_text())
    assert [f["frame"] for f in stats["frames"]] == [2, 3]
    for key in ("interp_ms", "build_ms", "trace_ms", "shade_ms", "shadow_ms", "write_ms", "tri_tests",
                "mrays_per_s", "rays", "triangles"):
        assert key in stats["frames"][0]
    assert set(stats["summary"]) >= {"fps_raycast", "fps_full", "fps_wall", "compile_s"}
    # this process's peak memory, and per triangle beyond the process before the scene (Linux: /proc)
    if Path("/proc/self/status").exists():
        summary = stats["summary"]
        assert summary["peak_rss_bytes"] > 50 * 1024 ** 2 and summary["bytes_per_triangle"] > 0
        assert stats["runs"][-1]["peak_rss_bytes"] == summary["peak_rss_bytes"]
    # existing frames are never overwritten unless asked
    again = CliRunner().invoke(main, ["render", str(small_demo), "-o", str(out), "--frames", "2:3", "--quiet"])
    assert again.exit_code == 2 and "frame_0002.exr" in again.output and "--resume" in again.output
    resumed = CliRunner().invoke(main, ["render", str(small_demo), "-o", str(out), "--frames", "2:4", "--quiet", "--resume"])
    assert resumed.exit_code == 0 and (out / "frame_0004.exr").exists()


def test_bad_yaml_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("version: 1\ncamera: {eye: [0, 0, 1], look_at: [0, 0, 0]\n")
    res = CliRunner().invoke(main, ["check", str(bad)])
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "bad.yaml" in lines[0] and "Traceback" not in res.output


def test_unknown_key_is_named(small_demo):
    text = small_demo.read_text().replace("shininess: 48", "shinyness: 48")
    small_demo.write_text(text)
    res = CliRunner().invoke(main, ["check", str(small_demo)])
    assert res.exit_code == 2 and "materials.rubber.shinyness" in res.output and "unknown key" in res.output


def test_missing_mesh_and_decreasing_key_times_are_named(small_demo):
    original = small_demo.read_text()
    small_demo.write_text(original.replace("tube_003.obj", "nope.obj"))
    res = CliRunner().invoke(main, ["check", str(small_demo)])
    assert res.exit_code == 2 and "objects.1.keyframes.3.mesh" in res.output and "nope.obj" in res.output
    small_demo.write_text(original.replace("{t: 1.5, mesh: tube_003.obj}", "{t: 0.9, mesh: tube_003.obj}"))
    res = CliRunner().invoke(main, ["check", str(small_demo)])
    assert res.exit_code == 2 and "objects.1.keyframes.3" in res.output


def test_check_summarises(small_demo):
    res = CliRunner().invoke(main, ["check", str(small_demo)])
    assert res.exit_code == 0 and "7330 triangles" in res.output and "deforming" in res.output


def test_bench_writes_spec_rows(tmp_path):
    out = tmp_path / "bench.json"
    res = CliRunner().invoke(main, ["bench", "--scene", "demo", "--res", "32", "--frames", "2",
                                    "--packet", "8,16", "--json", str(out), "--plot", str(tmp_path / "b.png")])
    assert res.exit_code == 0, res.output
    rows = json.loads(out.read_text())
    assert [r["packet"] for r in rows] == [8, 16]
    for key in ("scene", "accel", "packet", "threads", "triangles", "build_ms", "trace_ms", "shade_ms",
                "shadow_ms", "fps_raycast", "fps_full", "mrays_per_s", "tri_tests",
                "write_ms", "shadow_mrays_per_s"):
        assert key in rows[0]
    assert rows[0]["triangles"] == 7330 and rows[0]["fps_raycast"] > 0
    assert rows[0]["write_ms"] > 0 and rows[0]["shadow_mrays_per_s"] > 0
    assert (tmp_path / "b.png").stat().st_size > 1000


def test_bench_rejects_unknown_scene_and_packet():
    assert CliRunner().invoke(main, ["bench", "--scene", "nope"]).exit_code == 2
    assert CliRunner().invoke(main, ["bench", "--packet", "12"]).exit_code == 2


def test_bench_error_reports_orders_and_writes_json_and_plot(tmp_path):
    import json
    plot = tmp_path / "err.png"
    # --quick: the same studies and code with fewer points (the full run took 340 s of the suite)
    res = CliRunner().invoke(main, ["bench", "--scene", "torus", "--error", "--quick", "--res", "64",
                                    "--plot", str(plot)])
    assert res.exit_code == 0, res.output
    report = json.loads(plot.with_suffix(".json").read_text())
    assert plot.stat().st_size > 10000
    orders = report["scenes"]["torus"]["orders"]
    assert abs(orders["linear"]["measured"] - 2) < 0.2 and abs(orders["cubic"]["measured"] - 4) < 0.3
    assert "order measured" in res.output and "bounce" in res.output
    pchip = [r for r in report["bounce"] if r["method"] == "pchip"]
    assert pchip and all(r["min_height"] >= 0 for r in pchip)
    # the image's own error falls with samples per pixel, and the report says how fast
    spp = report["image"]["spp"]["torus"]
    assert [r["spp"] for r in spp] == [1, 4, 16] and report["quick"]
    assert spp[-1]["rmse"] < 0.5 * spp[0]["rmse"] and report["image"]["slopes"]["torus spp"] < -0.2
    assert "image error vs spp" in res.output
    # motion blur: passes, each at its own shutter time, converge to the many-pass frame
    blur = report["image"]["motion_blur"]["torus (shutter 0.5)"]
    assert [r["spp"] for r in blur] == [1, 4, 16] and blur[-1]["rmse"] < 0.5 * blur[0]["rmse"]
    assert "torus (shutter 0.5): image error vs passes" in res.output
    # float32 precision: scale-free when the scene sits at the origin, breaking up far from it
    rows = {(r["scale"], r["offset"]): r for r in report["precision"]["rows"]}
    assert all(rows[s, 0.0]["median_rel"] < 1e-6 and rows[s, 0.0]["hit_mismatch"] == 0 for s in (1e-4, 1.0, 1e4))
    assert rows[1e-4, 1e6]["hit_mismatch"] > 0.1 and rows[1.0, 1e6]["p99_rel"] > 1e-3


def test_render_with_the_kdtree(small_demo, tmp_path):
    out = tmp_path / "kd"
    res = CliRunner().invoke(main, ["render", str(small_demo), "-o", str(out), "--frames", "2:2",
                                    "--accel", "kdtree", "--quiet"])
    assert res.exit_code == 0, res.output
    stats = json.loads((out / "stats.json").read_text())
    assert stats["accel"] == "kdtree" and stats["frames"][0]["kd_nodes"] > 0
    assert len(list(out.glob("*.exr"))) == 1


@pytest.mark.parametrize("compression", sorted(c for c, (_, kind) in COMPRESSIONS.items() if kind == "lossless"))
def test_lossless_compressions_round_trip_exactly(tmp_path, compression):
    rng = np.random.default_rng(1)
    rgba = rng.random((37, 41, 4)).astype(np.float32) * 4
    z = rng.random((37, 41)).astype(np.float32) * 1e3
    z[::5, ::3] = np.inf
    path = tmp_path / "f.exr"
    write_exr(str(path), {"RGBA": rgba, "Z": z}, {"frustrace:frame": 1}, compression)
    names, px, spec = read_exr(str(path))
    assert names == ["R", "G", "B", "A", "Z"]
    assert spec.getattribute("compression") == compression
    assert np.array_equal(px[..., :4], rgba.astype(np.float16).astype(np.float32))
    assert np.array_equal(px[..., 4], z)
    assert [p.name for p in tmp_path.iterdir()] == ["f.exr"]


def test_unknown_compression_is_a_scene_error(small_demo):
    small_demo.write_text(small_demo.read_text().replace("aovs: [N, id]", "aovs: [N, id], compression: lzma"))
    result = CliRunner().invoke(main, ["check", str(small_demo)])
    assert result.exit_code == 2
    assert "output.compression" in result.output


def _write_png(path, rgba_u8):
    import OpenImageIO as oiio
    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(rgba_u8.shape[1], rgba_u8.shape[0], rgba_u8.shape[2], "uint8")
    spec.attribute("oiio:UnassociatedAlpha", 1)       # the bytes as given, as a paint program saves them
    assert out.open(str(path), spec) and out.write_image(rgba_u8)
    out.close()


def test_8bit_textures_are_decoded_from_srgb_and_alpha_does_not_scale_colour(tmp_path):
    from raycore.images.image_io import read_texture
    px = np.zeros((2, 2, 4), np.uint8)
    px[..., :3] = 128
    px[..., 3] = [[255, 0], [64, 128]]
    _write_png(tmp_path / "t.png", px)
    rgb = read_texture(tmp_path / "t.png")
    # sRGB 128/255 is 0.2158 linear, whatever the alpha
    np.testing.assert_allclose(rgb, 0.21586, atol=2e-4)
    np.testing.assert_allclose(read_texture(tmp_path / "t.png", "linear"), 128 / 255, atol=1e-6)


def test_float_textures_stay_linear(tmp_path):
    from raycore.images.image_io import read_texture
    vals = np.full((3, 3, 4), 0.5, np.float32)
    write_exr(str(tmp_path / "t.exr"), {"RGBA": vals}, {})
    np.testing.assert_allclose(read_texture(tmp_path / "t.exr"), 0.5)
    np.testing.assert_allclose(read_texture(tmp_path / "t.exr", "srgb"), 0.21404, atol=1e-4)


def test_texture_write_read_round_trip(tmp_path):
    from raycore.images.image_io import read_texture, write_texture
    lin = np.random.default_rng(3).random((5, 7, 3)).astype(np.float32)
    write_texture(str(tmp_path / "t.png"), lin)
    np.testing.assert_allclose(read_texture(tmp_path / "t.png"), lin, atol=0.01)


def test_fps_wall_leaves_the_compile_time_out(small_demo, tmp_path, monkeypatch):
    """A slow warm-up (a cold numba cache) is reported as warm_up_s, not
    counted in the run's wall clock or fps_wall; compile_s is what numba
    compiled in it (nothing, for this stand-in)."""
    import json
    import time as time_module

    import anim.render.job as job_module

    def slow_warm_up(*args, **kwargs):
        time_module.sleep(1.5)
        return 1.5, {}
    monkeypatch.setattr(job_module, "warm_up", slow_warm_up)
    t0 = time_module.perf_counter()
    res = CliRunner().invoke(main, ["render", str(small_demo), "-o", str(tmp_path / "o"), "--frames", "0:1", "-q"])
    elapsed = time_module.perf_counter() - t0
    assert res.exit_code == 0, res.output
    stats = json.loads((tmp_path / "o" / "stats.json").read_text())
    run = stats["runs"][-1]
    # the run's wall clock is the command's less the warm-up, however slow the host
    assert run["warm_up_s"] == 1.5 and run["compile_s"] == 0.0 and run["wall_s"] <= elapsed - 1.5
    assert stats["summary"]["warm_up_s"] == 1.5
