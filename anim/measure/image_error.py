"""`bench --error`, the image part: error of the frame itself against run
time, for the knobs that trade one for the other.

* samples per pixel (Hammersley sub-pixel samples) 1..64, against a
  reference of REF_SPP samples;
* area-light samples 1..64 (emitters, each one more shadow pass), on the
  scene with its first point light made a 1x1 area light, against
  REF_LIGHT_SAMPLES emitters.

Error is over the linear RGB of the whole frame: RMSE, max, and PSNR with a
peak of 1. The measured slope of log RMSE against log ms per frame goes
beside the expected ones: -1/2 for independent random samples; stratified
and low-discrepancy samples do better, about -3/4 at edges in 2D.
"""
import tempfile
import time
from pathlib import Path

import numpy as np

from anim import builtin
from anim.render.renderer import SceneRenderer
from anim.render.settings import config_of, shading_of
from anim.scene import AnimatedScene
from anim.schema import Light

SPPS = (1, 2, 4, 8, 16, 32, 64)
REF_SPP = 256
LIGHT_SAMPLES = (1, 2, 4, 8, 16, 32, 64)
REF_LIGHT_SAMPLES = 512
RES = 192
EXPECTED_SLOPES = {"random": -0.5, "stratified at edges": -0.75}


def _frame(scene, t, res, repeats=3, **overrides):
    """(rgb (H, W, 3) f64, median ms per frame) of the frame at t, compile excluded."""
    cfg = config_of(scene, width=res, height=res, aovs=(), **overrides)
    renderer = SceneRenderer(scene, cfg, shading_of(scene))
    renderer.render(t)                                          # warm-up
    ms, rgb = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = renderer.render(t)[1]
        ms.append((time.perf_counter() - t0) * 1e3)
        rgb = result.rgba[..., :3].astype(np.float64)
    return rgb, float(np.median(ms))


def _error(rgb, ref):
    d = rgb - ref
    rmse = float(np.sqrt(np.mean(d * d)))
    return {"rmse": rmse, "max": float(np.abs(d).max()),
            "psnr": float(20 * np.log10(1.0 / rmse)) if rmse > 0 else float("inf")}


def slope(rows, x="ms", y="rmse"):
    """Least-squares slope of log y against log x over the rows with y > 0."""
    pts = [(r[x], r[y]) for r in rows if r[y] > 0 and r[x] > 0]
    if len(pts) < 2:
        return float("nan")
    lx, ly = np.log(np.array(pts)).T
    return float(np.polyfit(lx, ly, 1)[0])


def spp_study(scene, t, res=RES):
    ref, _ = _frame(scene, t, res, repeats=1, spp=REF_SPP)
    rows = []
    for spp in SPPS:
        rgb, ms = _frame(scene, t, res, spp=spp)
        rows.append({"spp": spp, "ms": ms, **_error(rgb, ref)})
    return rows


def area_lit(scene):
    """The scene with its first point light made a 1x1 rectangle of the same
    intensity, centred where the point was; None if it has no point light."""
    for i, light in enumerate(scene.spec.lights):
        if light.type == "point":
            p = np.asarray(light.position, float)
            scene.spec.lights[i] = Light(type="area", corner=tuple(p - (0.5, 0, 0.5)), edge_u=(1, 0, 0),
                                         edge_v=(0, 0, 1), color=light.color, intensity=light.intensity)
            return i
    return None


def light_samples_study(scene, index, t, res=RES):
    def with_samples(n):
        scene.spec.lights[index] = scene.spec.lights[index].model_copy(update={"samples": n})
    with_samples(REF_LIGHT_SAMPLES)
    ref, _ = _frame(scene, t, res, repeats=1)
    rows = []
    for n in LIGHT_SAMPLES:
        with_samples(n)
        rgb, ms = _frame(scene, t, res)
        rows.append({"light_samples": n, "ms": ms, **_error(rgb, ref)})
    return rows


def run_image_study(names, res=RES):
    """{'spp': {scene: rows}, 'light_samples': {scene: rows}, 'slopes': {...}}
    for the built-in scenes named; the area-light study on the first of them
    that has a point light."""
    out = {"resolution": res, "ref_spp": REF_SPP, "ref_light_samples": REF_LIGHT_SAMPLES,
           "expected_slopes": EXPECTED_SLOPES, "spp": {}, "light_samples": {}, "slopes": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            if name not in builtin.ALL:
                continue
            scene = AnimatedScene(builtin.get(name).write(Path(tmp) / name))
            t = scene.time_of(scene.frame_numbers[len(scene.frame_numbers) // 3])
            out["spp"][name] = spp_study(scene, t, res)
            out["slopes"][f"{name} spp"] = slope(out["spp"][name])
            if not out["light_samples"]:
                index = area_lit(scene)
                if index is not None:
                    rows = light_samples_study(scene, index, t, res)
                    out["light_samples"][f"{name} (area light)"] = rows
                    out["slopes"][f"{name} light samples"] = slope(rows)
    return out
