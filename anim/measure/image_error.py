"""`bench --error`, the image part: error of the frame itself against run
time, for the knobs that trade one for the other.

* samples per pixel (Hammersley sub-pixel samples) 1..64, against a
  reference of REF_SPP samples, and the error budget (render.max_error) at
  MAX_ERRORS, with the rays uniform sampling needs for the same RMSE;
* area-light samples 1..64 (emitters, each one more shadow pass), on the
  scene with its first point light made a 1x1 area light, against
  REF_LIGHT_SAMPLES emitters;
* motion blur (a shutter of MOTION_SHUTTER frame intervals): passes 1..64,
  each at its own shutter time, against REF_SPP passes, on the first scene.

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
MAX_ERRORS = (0.04, 0.02, 0.01, 0.005, 0.0025)
# the area light's samples in the area-lit scene's spp and budget studies, and
# the probes among them (render.light_probes): as a user would set them
AREA_SAMPLES = 16
AREA_PROBES = 4
RES = 192
MOTION_SHUTTER = 0.5           # the film "180 degree" shutter
EXPECTED_SLOPES = {"random": -0.5, "stratified at edges": -0.75}


def _frame(scene, t, res, repeats=3, **overrides):
    """(rgb (H, W, 3) f64, median ms per frame, rays: camera + shadow) of the
    frame at t, compile excluded."""
    cfg = config_of(scene, width=res, height=res, aovs=(), **overrides)
    renderer = SceneRenderer(scene, cfg, shading_of(scene))
    renderer.render(t)                                          # warm-up
    ms, rgb = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = renderer.render(t)[1]
        ms.append((time.perf_counter() - t0) * 1e3)
        rgb = result.rgba[..., :3].astype(np.float64)
    rays = int(result.counters["rays"] + result.counters["shadow_rays"])
    return rgb, float(np.median(ms)), rays


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


# `bench --error --quick`: the same studies with fewer and cheaper points
QUICK = {"spps": (1, 4, 16), "ref_spp": 64, "light_samples": (1, 4, 16), "ref_light_samples": 128,
         "max_errors": (0.04, 0.01)}
FULL = {"spps": SPPS, "ref_spp": REF_SPP, "light_samples": LIGHT_SAMPLES, "ref_light_samples": REF_LIGHT_SAMPLES,
        "max_errors": MAX_ERRORS}


def motion_blur_study(scene, t, res=RES, sizes=FULL):
    """Rows of passes (spp) under a MOTION_SHUTTER shutter, against the
    frame of ref_spp passes."""
    ref = _frame(scene, t, res, repeats=1, spp=sizes["ref_spp"], shutter=MOTION_SHUTTER)[0]
    rows = []
    for spp in sizes["spps"]:
        rgb, ms, rays = _frame(scene, t, res, spp=spp, shutter=MOTION_SHUTTER)
        rows.append({"spp": spp, "ms": ms, "rays": rays, **_error(rgb, ref)})
    return rows


def spp_study(scene, t, res=RES, sizes=FULL):
    """(rows for uniform spp, rows for the error budget), against one reference."""
    ref = _frame(scene, t, res, repeats=1, spp=sizes["ref_spp"])[0]
    rows = []
    for spp in sizes["spps"]:
        rgb, ms, rays = _frame(scene, t, res, spp=spp)
        rows.append({"spp": spp, "ms": ms, "rays": rays, **_error(rgb, ref)})
    return rows, budget_study(scene, t, res, ref, rows, sizes["max_errors"])


def budget_study(scene, t, res, ref, uniform_rows, max_errors=MAX_ERRORS):
    """The error budget (render.max_error) at MAX_ERRORS: error, ms, rays,
    and the rays uniform spp needs for the same RMSE (log-log interpolated
    along uniform_rows; None outside their range), so ray_savings =
    uniform rays / budget rays."""
    rows = []
    for e in max_errors:
        rgb, ms, rays = _frame(scene, t, res, max_error=e)
        err = _error(rgb, ref)
        same = rays_for_rmse(uniform_rows, err["rmse"])
        rows.append({"max_error": e, "ms": ms, "rays": rays, **err, "uniform_rays_same_rmse": same,
                     "ray_savings": same / rays if same else None})
    return rows


def rays_for_rmse(rows, rmse):
    """Rays uniform sampling needs for `rmse`: log-log interpolation between
    the two spp rows that bracket it (None if none do)."""
    pts = sorted((r["rmse"], r["rays"]) for r in rows if r["rmse"] > 0)
    for (e0, n0), (e1, n1) in zip(pts, pts[1:]):
        if e0 <= rmse <= e1:
            if e1 == e0:
                return float(n0)
            w = (np.log(rmse) - np.log(e0)) / (np.log(e1) - np.log(e0))
            return float(np.exp(np.log(n0) + w * (np.log(n1) - np.log(n0))))
    return None


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


def light_samples_study(scene, index, t, res=RES, sizes=FULL):
    def with_samples(n):
        scene.spec.lights[index] = scene.spec.lights[index].model_copy(update={"samples": n})
    with_samples(sizes["ref_light_samples"])
    ref = _frame(scene, t, res, repeats=1)[0]
    rows = []
    for n in sizes["light_samples"]:
        with_samples(n)
        rgb, ms, rays = _frame(scene, t, res)
        rows.append({"light_samples": n, "ms": ms, "rays": rays, **_error(rgb, ref)})
    return rows


def run_image_study(names, res=RES, sizes=FULL):
    """{'spp': {scene: rows}, 'budget': {scene: rows}, 'light_samples':
    {scene: rows}, 'slopes': {...}} for the built-in scenes named; on the
    first of them that has a point light, that light made an area light:
    light samples 1..64, then spp and the error budget with AREA_SAMPLES
    emitters, AREA_PROBES of them probes."""
    out = {"resolution": res, "ref_spp": sizes["ref_spp"], "ref_light_samples": sizes["ref_light_samples"],
           "expected_slopes": EXPECTED_SLOPES, "spp": {}, "budget": {}, "light_samples": {}, "motion_blur": {},
           "slopes": {}}

    def pixel_studies(label, scene, t):
        out["spp"][label], out["budget"][label] = spp_study(scene, t, res, sizes)
        out["slopes"][f"{label} spp"] = slope(out["spp"][label])
        out["slopes"][f"{label} budget"] = slope(out["budget"][label])

    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            if name not in builtin.ALL:
                continue
            scene = AnimatedScene(builtin.get(name).write(Path(tmp) / name))
            t = scene.time_of(scene.frame_numbers[len(scene.frame_numbers) // 3])
            pixel_studies(name, scene, t)
            if not out["motion_blur"]:
                label = f"{name} (shutter {MOTION_SHUTTER:g})"
                out["motion_blur"][label] = motion_blur_study(scene, t, res, sizes)
                out["slopes"][f"{label} motion blur"] = slope(out["motion_blur"][label])
            if not out["light_samples"]:
                index = area_lit(scene)
                if index is not None:
                    label = f"{name} (area light)"
                    rows = light_samples_study(scene, index, t, res, sizes)
                    out["light_samples"][label] = rows
                    out["slopes"][f"{label} light samples"] = slope(rows)
                    scene.spec.lights[index] = scene.spec.lights[index].model_copy(
                        update={"samples": AREA_SAMPLES})
                    scene.spec.render = scene.spec.render.model_copy(update={"light_probes": AREA_PROBES})
                    pixel_studies(label, scene, t)
    return out
