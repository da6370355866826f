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


class InstancedBruteForcePeer(BruteForcePeer):
    """A peer that takes instanced_parts as they are handed to Mitsuba: it
    places the prototypes itself and reports the scene's triangle ids."""
    name = "bruteforce-instances"

    def build_instanced(self, parts):
        tris, ids = [parts["vertices"][parts["faces"]].reshape(-1, 9)], [parts["rest_ids"]]
        for pv, pf, mats, first in parts["groups"]:
            placed = np.einsum("nij,vj->nvi", mats[:, :, :3], pv.astype(np.float64)) + mats[:, None, :, 3]
            tris.append(placed[:, pf].reshape(-1, 9))
            ids.append(first + np.arange(len(mats) * len(pf)))
        self.tri = np.concatenate(tris).astype(np.float32)
        self.ids = np.concatenate(ids)

    def closest(self, o, d):
        prim, t = super().closest(o, d)
        return np.where(prim >= 0, self.ids[np.maximum(prim, 0)], -1), t


def test_a_peer_with_instancing_sees_the_scene_the_flattened_peers_see(tmp_path):
    """instanced_parts (what Mitsuba's shapegroups get): prototypes, per-copy
    transforms and the scene's triangle ids, placed by the peer, give the
    flattened peer's triangle ids and depth on every pixel."""
    from anim.measure.peers import instanced_parts, peer_frame
    from anim.render.settings import shading_of
    from anim.scene import AnimatedScene
    (tmp_path / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
    rng = np.random.default_rng(8)
    keys = "".join(f"        - {{t: {t}, translation: {rng.uniform(-2, 2, (30, 3)).round(3).tolist()}, "
                   f"rotation: {rng.normal(size=(30, 4)).round(3).tolist()}}}\n" for t in (0, 1))
    path = tmp_path / "s.yaml"
    path.write_text(f"""version: 1
camera: {{eye: [0, 0, 8], look_at: [0, 0, 0], fov: 45}}
lights: [{{position: [2, 3, 6], intensity: 20}}]
objects:
  - name: ground
    mesh: tri.obj
    transform: {{scale: {{keys: [[0, 4, 4, 0.1]]}}, translation: {{keys: [[0, -2, -2, -1]]}}}}
  - name: copies
    mesh: tri.obj
    instances:
      keys:
{keys}""")
    scene = AnimatedScene(path)
    lights = shading_of(scene).lights
    t = 0.4
    pose = CameraPose(*scene.camera_at(t))
    parts = instanced_parts(scene, t)
    assert len(parts["groups"]) == 1 and len(parts["rest_ids"]) == 4
    flat, inst = BruteForcePeer(), InstancedBruteForcePeer()
    timings_f, depth_f = peer_frame(flat, scene.vertices_at(t), scene.faces, pose, 24, 24, lights)
    timings_i, depth_i = peer_frame(inst, scene.vertices_at(t), scene.faces, pose, 24, 24, lights, parts)
    assert np.isfinite(depth_f).mean() > 0.2
    np.testing.assert_allclose(depth_i, depth_f, rtol=1e-5)
    o, d = camera_rays(pose, 24, 24)
    np.testing.assert_array_equal(inst.closest(o, d)[0], flat.closest(o, d)[0])
    assert timings_i["shadow_rays"] == timings_f["shadow_rays"]
