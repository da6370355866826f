"""`bench --peers` harness, without any peer package: the rays it hands a
peer are frustrace's own, and a brute-force peer run through it agrees with
frustrace pixel for pixel."""
import numpy as np
from click.testing import CliRunner

from anim.measure.peers import camera_rays, shadow_rays
from oracles import brute_force_closest, kernel_camera_rays
from raycore.geometry.camera import camera_basis
from raycore.frame import CameraPose


class BruteForcePeer:
    """A 'peer' that tests every ray against every triangle (tests/oracles.py)."""
    name = "bruteforce"

    def build(self, vertices, faces):
        self.tri = vertices[faces].reshape(-1, 9).astype(np.float32)

    def closest(self, o, d):
        t, prim, _, _ = brute_force_closest(o, d, np.zeros(len(o), np.float32),
                                            np.full(len(o), np.inf, np.float32), self.tri)
        return prim, t

    def occluded(self, o, d, length):
        return brute_force_closest(o, d, np.zeros(len(o), np.float32), length, self.tri)[1] >= 0


def test_camera_rays_are_the_renderers_rays():
    pose = CameraPose((0.3, 1.0, 4.0), (0.0, 0.2, 0.0), (0, 1, 0), 50.0)
    o, d = camera_rays(pose, 24, 16)
    cam = camera_basis(pose.eye, pose.look_at, pose.up, pose.fov, 24, 16)
    ko, kd = kernel_camera_rays(cam, 24, 16, np.float32(0.5), np.float32(0.5))
    np.testing.assert_array_equal(o, ko)
    np.testing.assert_allclose(d, kd, atol=2e-7)


def test_shadow_rays_leave_the_lit_side_and_stop_at_the_light():
    p = np.array([[0, 0, 0], [1, 0, 0]], np.float32)
    n = np.array([[0, 1, 0], [0, 1, 0]], np.float32)
    view = np.array([[0, -1, 0], [0, 1, 0]], np.float32)      # second point seen from below
    light = np.array([0, 0, 5, 0, 1, 1, 1, 0], np.float32)
    o, d, length = shadow_rays(p, n, view, light, extent=10.0)
    assert len(o) == 1 and o[0, 1] > 0                        # the back-lit point casts none
    np.testing.assert_allclose(o[0] + d[0] * length[0], light[1:4], atol=1e-5)
    sun = np.array([1, 0, -1, 0, 1, 1, 1, 0], np.float32)     # travelling down: lights the top
    o, d, length = shadow_rays(p, n, view, sun, extent=10.0)
    assert len(o) == 1 and np.isinf(length[0]) and d[0, 1] == 1


def test_bench_peers_rows_agree_with_frustrace(monkeypatch, tmp_path):
    import json
    import anim.measure.peers
    from cli.main import main
    monkeypatch.setattr(anim.measure.peers, "available_peers", lambda threads: [BruteForcePeer()])
    out = tmp_path / "bench.json"
    res = CliRunner().invoke(main, ["bench", "--scene", "toys", "--res", "16", "--frames", "1",
                                    "--packet", "8", "--peers", "--json", str(out),
                                    "--plot", str(tmp_path / "b.png")])
    assert res.exit_code == 0, res.output
    rows = json.loads(out.read_text())
    ours, peer = rows
    assert peer["accel"] == "bruteforce" and peer["peer"] and peer["shade_ms"] == 0
    assert peer["hit_agreement"] == 1.0
    assert peer["shadow_mrays_per_s"] > 0 and peer["interp_ms"] == ours["interp_ms"]
    assert ours["vs_best_peer"] == ours["fps_full"] / peer["fps_full"]
    assert "full / best peer" in res.output


def test_bench_peers_without_any_peer_installed_is_a_usage_error(monkeypatch):
    import anim.measure.peers
    from cli.main import main
    monkeypatch.setattr(anim.measure.peers, "available_peers", lambda threads: [])
    res = CliRunner().invoke(main, ["bench", "--scene", "demo", "--peers"])
    assert res.exit_code == 2 and "frustrace[peers]" in res.output
