"""Rigid objects moved in one batch equal each object's own evaluation
(per-object curves and scipy rotations) at any time, for every track kind."""
import numpy as np

from anim.builtin.authoring import write_obj
from anim.scene import AnimatedScene
from anim.tracks import trs_matrix


def test_batch_matrices_equal_per_object_evaluation(tmp_path, rng):
    write_obj(tmp_path / "m.obj", rng.normal(size=(5, 3)), [[0, 1, 2], [2, 3, 4]])
    objects = []
    methods = ["linear", "catmull-rom", "cubic", "pchip", "akima", "centripetal"]
    for i in range(24):
        n = int(rng.integers(1, 7))
        times = np.cumsum(rng.uniform(0.05, 0.6, n)) - 0.3
        lines = [f"  - name: o{i}", "    mesh: m.obj", f"    extrapolate: {'loop' if i % 2 else 'clamp'}", "    transform:"]
        if i % 5 != 1:
            keys = [[float(t), *map(float, rng.normal(size=3) * 100)] for t in times]
            lines.append(f"      translation: {{interpolation: {methods[i % 6]}, keys: {keys}}}")
        if i % 5 != 2:
            q = rng.normal(size=(n, 4))
            if n > 1 and i % 3 == 0:
                q[1] = -q[0]                                   # antipodal pair
            keys = [[float(t), *map(float, qq)] for t, qq in zip(times, q)]
            interp = "spline" if i % 4 == 0 else "slerp"
            lines.append(f"      rotation: {{interpolation: {interp}, keys: {keys}}}")
        if i % 5 == 3:
            keys = [[float(t), *map(float, rng.uniform(0.5, 2, 3))] for t in times]
            lines.append(f"      scale: {{keys: {keys}}}")
        if len(lines) == 4:
            lines.append("      scale: {keys: [[0, 1, 1, 1], [1, 2, 2, 2]]}")
        objects.append("\n".join(lines))
    path = tmp_path / "s.yaml"
    path.write_text("version: 1\ncamera: {eye: [0, 0, 5], look_at: [0, 0, 0]}\nobjects:\n"
                    + "\n".join(objects) + "\n")
    scene = AnimatedScene(path)
    batch = scene.rigid_batch
    assert batch is not None and len(batch.objects) == len(scene.moving)
    for t in np.concatenate([rng.uniform(-2, 4, 40), [-0.3, 0.0, 1.0], times[-1:]]):
        mats = batch.matrices(t)
        for o, m in zip(batch.objects, mats):
            np.testing.assert_allclose(m, trs_matrix(o.translation, o.rotation, o.scale, t),
                                       rtol=1e-12, atol=1e-9)
        v = scene.vertices_at(t).copy()
        for o in batch.objects:
            ref = np.empty((len(o.base), 3), np.float32)
            o.place(t, ref)
            np.testing.assert_allclose(v[o.offset:o.offset + len(o.base)], ref, rtol=1e-6, atol=1e-4)
