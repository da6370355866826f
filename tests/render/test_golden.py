"""Small golden images: every built-in scene at 64x64, one frame, compared
with frames rendered before (tests/golden/NAME.npy, RGBA as float16), so that
any change to what a frame looks like shows up here, not only in the oracle
tests of each kernel. A deliberate change regenerates them:
FRUSTRACE_UPDATE_GOLDEN=1 pytest tests/render/test_golden.py (and says why in its commit)."""
import os
from pathlib import Path

import numpy as np
import pytest

from anim import builtin
from anim.scene import AnimatedScene
from anim.render.renderer import SceneRenderer
from anim.render.settings import config_of, shading_of

GOLDEN = Path(__file__).resolve().parents[1] / "golden"
SIZE = 64


@pytest.mark.parametrize("name", list(builtin.ALL))
def test_builtin_scene_looks_as_it_did(tmp_path, name):
    scene = AnimatedScene(builtin.get(name).write(tmp_path / name))
    frame = scene.frame_numbers[len(scene.frame_numbers) // 3]
    cfg = config_of(scene, width=SIZE, height=SIZE, aovs=())
    rgba = SceneRenderer(scene, cfg, shading_of(scene)).render(scene.time_of(frame))[1].rgba
    got = rgba.astype(np.float16)                         # as the EXR stores it
    path = GOLDEN / f"{name}.npy"
    if os.environ.get("FRUSTRACE_UPDATE_GOLDEN"):
        np.save(path, got)
    want = np.load(path)
    diff = np.abs(got.astype(np.float32) - want.astype(np.float32))
    # half-float steps, and a shadow ray grazing an edge flipping one pixel
    assert (diff.max(axis=2) > 1e-2).sum() <= 2, np.argwhere(diff.max(axis=2) > 1e-2)
    assert np.median(diff) <= 1e-3 and got.std() > 0.01
