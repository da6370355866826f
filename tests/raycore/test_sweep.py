"""The one-sweep path (raycore/sweep.py: gather, shadows, shading and
pixels block by block) against the phase by phase path (visible_surface,
the shadow pass, shade_samples, write_pixels), which the frame takes when
AOVs are asked for: the same pictures and the same shadow rays."""
import numpy as np
import pytest

from test_shade import sphere_on_floor


def _both(cfg_kw, lights=None, width=80, height=64):
    """(frame through the sweep, frame through the phases), each checked to
    have taken its path."""
    import raycore.frame as frame
    from raycore.config import RenderConfig
    from raycore.frame import CameraPose, render_frame
    calls = []
    sweep_image = frame.shade_image
    geom, shading, _ = sphere_on_floor()
    if lights is not None:
        shading = shading._replace(lights=lights)
    pose = CameraPose((0.5, 1.5, 4.0), (0.0, -0.3, 0.0), (0, 1, 0), 45.0)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(frame, "shade_image", lambda *a: calls.append(1) or sweep_image(*a))
        sweep = render_frame(geom, shading, pose, RenderConfig(width=width, height=height, packet=16, **cfg_kw))
        passes = len(calls)
        phased = render_frame(geom, shading, pose, RenderConfig(width=width, height=height, packet=16,
                                                                aovs=("id",), **cfg_kw))
    assert passes == cfg_kw.get("spp", 1) and len(calls) == passes
    return sweep, phased


def _same_pictures(a, b):
    # the view direction is rounded once with and once without fused
    # multiply-adds (ulps of Z); colours are the same sums
    np.testing.assert_allclose(a.rgba, b.rgba, rtol=1e-5, atol=1e-6)
    assert np.array_equal(np.isinf(a.z), np.isinf(b.z))
    np.testing.assert_allclose(a.z[np.isfinite(a.z)], b.z[np.isfinite(b.z)], rtol=1e-6)


@pytest.mark.parametrize("cfg_kw", [{}, {"spp": 4}, {"shadows": False}],
                         ids=["one sample", "four samples accumulate", "no shadows"])
def test_the_sweep_paints_what_the_phases_paint(cfg_kw):
    """Image sizes that are no multiple of the 32-pixel blocks (edge blocks
    part empty), a textured and a flat material, a point and a directional
    light: the same RGBA and Z, the same shadow rays and skipped rays."""
    sweep, phased = _both(cfg_kw, width=80, height=45)
    assert "id" in phased.aovs and not sweep.aovs
    _same_pictures(sweep, phased)
    hit = np.isfinite(sweep.z)
    assert 0.3 < hit.mean() < 0.98
    for key in ("rays", "shadow_rays", "shadow_rays_skipped"):
        assert sweep.counters[key] == phased.counters[key], key
    if cfg_kw.get("shadows", True):
        assert sweep.counters["shadow_rays"] > 0 and sweep.timings["shadow_ms"] > 0
        # some samples are shadowed (the sphere on the floor), some face away
        assert sweep.counters["shadow_rays_skipped"] > 0
    else:
        assert sweep.counters["shadow_rays"] == 0 and sweep.timings["shadow_ms"] == 0


def test_a_dark_light_is_skipped_and_its_row_stays_dark():
    """A light of zero colour between two lit ones: not traced (the lit rows
    land in their own vis rows, out of order in the table), and it adds
    nothing; the picture is the phases' picture."""
    _, shading, _ = sphere_on_floor()
    lights = np.concatenate([shading.lights[:1], np.array([[0, -2, 3, 1, 0, 0, 0, 0]], np.float32),
                             shading.lights[1:]])
    sweep, phased = _both({}, lights=lights)
    _same_pictures(sweep, phased)
    assert sweep.counters["lights_skipped"] == 1
    lit_only, _ = _both({}, lights=lights[[0, 2]])
    np.testing.assert_array_equal(sweep.rgba, lit_only.rgba)
    assert sweep.counters["shadow_rays"] == lit_only.counters["shadow_rays"]


def test_a_sweep_without_shadow_rays_loads_no_packet_walk(tmp_path):
    """The sweep calls the shadow rays' packet walk through its address
    (bvh/trace.trace_block_lights_into), so a render without shadow rays
    neither compiles nor loads it; with them, it does."""
    import subprocess
    import sys
    from pathlib import Path
    demo = Path(__file__).resolve().parents[2] / "anim" / "builtin" / "demo" / "anim.yaml"
    script = ("import sys; from click.testing import CliRunner; from cli.main import main; "
              "import raycore.bvh.trace as t; "
              f"r = CliRunner().invoke(main, ['render', {str(demo)!r}, '-o', sys.argv[1], '--frames', '0:0', "
              "'--res', '32x24', '-q'] + sys.argv[2:]); assert r.exit_code == 0, r.output; "
              "print(len(t.trace_block_lights_into.overloads))")
    root = Path(__file__).resolve().parents[2]
    loaded = [subprocess.run([sys.executable, "-c", script, str(tmp_path / name), *extra], cwd=root,
                             capture_output=True, text=True, check=True).stdout.split()[-1]
              for name, extra in (("plain", ["--no-shadows"]), ("shadowed", []))]
    assert loaded == ["0", "1"], loaded


def test_the_kept_walk_address_is_the_one_for_the_sweeps_argument_types():
    """The sweep's shadow walk address (block_lights_entry) is the one numba
    gives for the full argument list the sweep passes it, whatever the
    number of lights."""
    from raycore.bvh.nodes import empty_bvh
    from raycore.bvh.trace import block_lights_entry, scratch, trace_block_lights_into
    from raycore.jit.counters import N_COUNTERS
    from raycore.jit.launch import native_entry
    from raycore.config import GATHER_BLOCK
    bvh = empty_bvh(1, 0)
    lights = np.zeros((2, 4), np.float32)
    rows = np.arange(2, dtype=np.int64)
    counters = np.zeros((4, N_COUNTERS), np.int64)
    m = GATHER_BLOCK * GATHER_BLOCK
    full = native_entry(trace_block_lights_into, bvh, lights, rows, np.int64(3), *(np.zeros((3, m), np.float32),) * 3,
                        np.zeros(m, np.float32), np.float32(1), np.zeros((3, m), np.float32), counters, np.int64(1),
                        *scratch.py_func(), np.zeros(1, np.int64))
    assert block_lights_entry(bvh, lights, rows, counters) == full
    five = np.zeros((5, 4), np.float32)
    assert block_lights_entry(bvh, five, np.arange(5, dtype=np.int64), counters) == full
