"""Linear vertex keyframes kept as float32 keys (anim/keyframes.py):
against the per-segment coefficients of interpolate.Curve (the oracle:
the same line, evaluated by Horner in float64), exact at the keys, clamped
and looped; keys spilled to a file past the memory budget give the same
frames and keep only a few keys in memory."""
import numpy as np
import pytest

from anim.interpolate import Curve
from anim.keyframes import KEPT, KeyStore, LinearKeys


def _keys(rng, k, n=500):
    return [(rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-3, 4)).astype(np.float32) for _ in range(k)]


@pytest.mark.parametrize("extrapolate", ["clamp", "loop"])
@pytest.mark.parametrize("budget", [1 << 30, 0])
def test_linear_keys_equal_the_curve_and_the_keys_exactly(extrapolate, budget):
    rng = np.random.default_rng(11)
    times = np.cumsum(rng.uniform(0.01, 1.0, 7)) - 0.3
    keys = _keys(rng, 7)
    store = KeyStore(budget)
    for v in keys:
        store.add(v)
    assert (store.file is not None) == (budget == 0)
    lazy = LinearKeys(times, store, extrapolate)
    oracle = Curve(times, np.stack(keys), "linear", extrapolate)
    got, want = np.empty_like(keys[0]), np.empty_like(keys[0])
    for t in np.concatenate([times, rng.uniform(times[0] - 2, times[-1] + 2, 40)]):
        lazy.eval_into(t, got)
        oracle.eval_into(t, want)
        np.testing.assert_allclose(got, want, rtol=3e-7, atol=3e-7 * np.abs(want).max())
    ends = len(times) - (extrapolate == "loop")            # looped, the last key's time is the first's
    for t, v in zip(times[:ends], keys[:ends]):
        lazy.eval_into(t, got)
        np.testing.assert_array_equal(got, v)                 # the keys, bit for bit
    if budget == 0:
        assert store.keys == [] and len(store.kept) <= KEPT


def test_a_scene_whose_keys_are_spilled_renders_the_same_vertices(tmp_path, monkeypatch):
    """Linear vertex keyframes past the budget go to a file: the object's
    vertices at every frame are those of the same scene kept in memory."""
    import anim.keyframes
    from anim.scene import AnimatedScene
    rng = np.random.default_rng(4)
    base = rng.normal(size=(60, 3))
    faces = "".join(f"f {a} {a + 1} {a + 2}\n" for a in range(1, 58, 3))
    keys = ""
    for k in range(12):
        v = base + 0.1 * k * rng.normal(size=base.shape)
        (tmp_path / f"k{k}.obj").write_text("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in v) + faces)
        keys += f"      - {{t: {k * 0.1:.1f}, mesh: k{k}.obj}}\n"
    path = tmp_path / "s.yaml"
    path.write_text(f"""version: 1
camera: {{eye: [0, 0, 9], look_at: [0, 0, 0]}}
objects:
  - name: soup
    interpolation: linear
    keyframes:
{keys}""")
    kept = AnimatedScene(path)
    monkeypatch.setattr(anim.keyframes, "KEY_BUDGET", 0)
    spilled = AnimatedScene(path)
    assert spilled.objects[0].curve.store.file is not None and kept.objects[0].curve.store.file is None
    for t in np.linspace(-0.1, 1.3, 31):
        np.testing.assert_array_equal(spilled.vertices_at(t), kept.vertices_at(t).copy())
