"""Vertex normals made only for the vertices the camera sees
(FrameStructures.lazy_normals: a scene that moves whole, with more
vertices than twice the pixels): the same frames, bit for bit, as normals
made for every vertex, through the sweep, the gather with AOVs, motion
blur's passes and the error budget's, on every structure. Where the BVH
traces every ray, the frame's corners are then left ungathered after the
first frame (FrameStructures.build's lazy corners): the same frames too,
with the BVH's trees refit or, when they must be, built again."""
import numpy as np
import pytest

from anim import builtin
from anim.render.renderer import SceneRenderer
from anim.render.settings import config_of, shading_of
from anim.scene import AnimatedScene


@pytest.mark.parametrize("settings", [
    dict(accel="grid"), dict(accel="bvh", aovs=("N",)), dict(accel="kdtree"),
    dict(accel="bvh", spp=4, shutter=0.5), dict(accel="grid", max_error=0.05),
    dict(accel="bvh", max_error=0.05, aovs=("P", "id")), dict(accel="bvh", rebuild=True)])
def test_normals_made_for_the_seen_vertices_give_the_same_frames(tmp_path, monkeypatch, settings):
    import raycore.bvh.scene as bvh_scene
    import raycore.structures as structures
    settings = dict(settings)
    if settings.pop("rebuild", False):
        monkeypatch.setattr(bvh_scene, "REBUILD_GROWTH", 0.0)            # every refit tree built again
    scene = AnimatedScene(builtin.get("torus").write(tmp_path / "torus"))      # moves whole
    frames = {}
    gathered = []
    real_corners = structures.FrameStructures.corners

    def corners(self):
        gathered.append(self.stale)
        return real_corners(self)

    monkeypatch.setattr(structures.FrameStructures, "corners", corners)
    for lazy in (False, True):
        monkeypatch.setattr(structures.FrameStructures, "lazy_normals", lambda self, n, lazy=lazy: lazy)
        cfg = config_of(scene, width=48, height=40, **{"aovs": (), **settings})
        renderer = SceneRenderer(scene, cfg, shading_of(scene))
        results = [renderer.render(scene.time_of(f))[1] for f in (3, 4, 5)]
        frames[lazy] = [(r.rgba.copy(), r.z.copy(), {k: v.copy() for k, v in r.aovs.items()}) for r in results]
        if lazy:
            state = renderer.structures.normal_state
            assert 0 < np.count_nonzero(state == 2) < len(state)        # some vertices seen, not all
            if cfg.accel == "bvh":
                # the last frame's corners were left to the hits (or gathered for a rebuild)
                rebuilt = bvh_scene.REBUILD_GROWTH == 0.0
                assert renderer.structures.stale is not rebuilt
                assert (True in gathered) is rebuilt
    for (a_rgba, a_z, a_aov), (b_rgba, b_z, b_aov) in zip(frames[False], frames[True]):
        np.testing.assert_array_equal(a_rgba, b_rgba)
        np.testing.assert_array_equal(a_z, b_z)
        assert a_aov.keys() == b_aov.keys() and all(np.array_equal(a_aov[k], b_aov[k]) for k in a_aov)
