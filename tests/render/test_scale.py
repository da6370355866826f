"""bench --scale (anim/measure/scale.py): the generated mesh has the size
asked for and moves between its keys, each size is measured in a process of
its own, and the table gives every phase's growth exponent."""
import json

import numpy as np
from click.testing import CliRunner

from anim.measure.scale import growth, torus
from cli.main import main


def test_the_generated_mesh_has_the_size_asked_for_and_deforms():
    for n in (500, 20000, 300000):
        verts, faces = torus(n, 0.0)
        assert abs(len(faces) - n) <= 0.02 * n + 64 and faces.max() < len(verts)
    a, _ = torus(5000, 0.0)
    b, _ = torus(5000, 0.5)
    assert np.abs(a - b).max() > 0.01


def test_growth_is_the_log_log_slope():
    rows = [{"triangles": 1000, "x": 2.0}, {"triangles": 10000, "x": 20.0}, {"triangles": 100000, "x": 400.0}]
    assert abs(growth(rows, "x") - 1.15051) < 1e-4              # log(200) / log(100)


def test_bench_scale_measures_each_size_in_its_own_process(tmp_path):
    out = tmp_path / "scale.json"
    res = CliRunner().invoke(main, ["bench", "--scale", "--scale-sizes", "600,2400", "--res", "32", "--frames", "1",
                                    "--threads", "1", "--json", str(out)])
    assert res.exit_code == 0, res.output
    result = json.loads(out.read_text())
    rows = result["rows"]
    assert [r["triangles"] for r in rows] == sorted(r["triangles"] for r in rows) and len(rows) == 2
    assert all(r["frame_ms"] > 0 and r["peak_rss_gb"] > 0 and r["keyframe_bytes"] > 0 for r in rows)
    assert set(result["growth"]) >= {"build_ms", "trace_ms", "shade_ms", "frame_ms"}
    assert "growth exponent" in res.output
    res = CliRunner().invoke(main, ["bench", "--scale", "--scale-sizes", "ten"])
    assert res.exit_code == 2 and "--scale-sizes" in res.output
