"""The error study of `frustrace bench --error`: interpolation error against run time on the
built-in scenes that know their exact motion, plus the bouncing-ball stiff
case, and the image's own error against run time (image_error.py: samples
per pixel, area-light samples) and float32 precision (precision.py), as one
report dict."""
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from anim import builtin
from anim.scene import AnimatedScene

from anim.measure.image_error import FULL, QUICK, RES, run_image_study
from anim.measure.interp_error import bounce_overshoot, measure
from anim.measure.precision import precision_study

FPS = 24.0     # frames per second used to amortise fitting over a period
MAX_VERTICES = 8192   # the method study runs on at most this many moving vertices (evenly subsampled)


def shipped_error(gen, n_times=40):
    """Error of the scene as written (its own keys, methods, skeletons and
    tracks) against its exact motion, at times between its keys; and the
    per-frame cost of producing its vertices."""
    with tempfile.TemporaryDirectory() as tmp:
        scene = AnimatedScene(gen.write(Path(tmp) / gen.name))
    times = eval_times(n_times, gen.period)
    err, cost = [], []
    for t in times:
        start = time.perf_counter()
        v = scene.vertices_at(t)
        cost.append(time.perf_counter() - start)
        err.append(np.linalg.norm(v.astype(np.float64) - gen.exact(t), axis=1))
    err = np.concatenate(err)
    return {"max_err": float(err.max()), "rms_err": float(np.sqrt(np.mean(err ** 2))),
            "interp_ms": float(np.median(cost) * 1e3)}


def eval_times(n, period):
    """n times in [0, period) that avoid any even key spacing (golden ratio)."""
    return period * ((0.5 + np.arange(n) * 0.6180339887498949) % 1.0)


def run_error_report(names, image_res=None, say=None, quick=False):
    """{'scenes': {name: measure(...)}, 'bounce': rows, 'image': ..., 'precision':
    ...} for scenes with exact motion; the image study at image_res pixels
    square (default image_error.RES). say(text): a progress line per step.
    quick: fewer key spacings, samples, budgets and precision cases, and a
    smaller reference (image_error.QUICK): the same tables in a fraction of
    the time, for a first look."""
    say = say or (lambda text: None)
    scenes = {}
    for name in names:
        if name not in builtin.SCENES:
            continue
        say(f"interpolation error: {name}")
        gen = builtin.get(name)
        n_moving = gen.exact_moving(0.0).shape[0]
        pick = np.linspace(0, n_moving - 1, min(n_moving, MAX_VERTICES)).astype(int)
        result = measure(lambda t: gen.exact_moving(t)[pick], 0.0, gen.period,
                         **({"key_counts": (5, 9, 17), "n_timed": 8} if quick else {}))
        frames = max(1.0, gen.period * FPS)
        for r in result["rows"]:                   # per-frame cost with the fit amortised
            r["frame_cost_ms"] = r["eval_ms"] + r["build_ms"] / frames
        result["vertices"] = int(len(pick))
        result["moving_vertices"] = int(n_moving)
        result["shipped"] = shipped_error(gen)
        scenes[name] = result
    say("interpolation error: the bouncing ball")
    bounce = bounce_overshoot()
    say(f"image error: spp, the error budget and area-light samples at {image_res or RES}^2")
    image = run_image_study(names, image_res or RES, QUICK if quick else FULL)
    say("float precision")
    return {"machine": platform.processor() or platform.machine(), "scenes": scenes, "quick": quick,
            "bounce": bounce, "image": image, "precision": run_precision_study(names, quick)}


def run_precision_study(names, quick=False):
    """precision.py's table for the first built-in scene named, at the frame
    the image study renders."""
    for name in names:
        if name in builtin.ALL:
            with tempfile.TemporaryDirectory() as tmp:
                scene = AnimatedScene(builtin.get(name).write(Path(tmp) / name))
            t = scene.time_of(scene.frame_numbers[len(scene.frame_numbers) // 3])
            tv = scene.vertices_at(t).astype(np.float64)[scene.faces].reshape(-1, 9)
            cases = {"res": 32, "scales": (1e-4, 1.0, 1e4), "offsets": (0.0, 1e6)} if quick else {}
            return {"scene": name, "rows": precision_study(tv, scene.camera_at(t), **cases)}
    return None
