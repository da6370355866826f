"""`frustrace bench --error`: the error study's tables, JSON and plot
(anim/measure/error_study.py computes it)."""
import json
from pathlib import Path

from rich.table import Table

from cli.report import Console


def print_report(report):
    console = Console() if Console().is_terminal else Console(width=160)
    for name, res in report["scenes"].items():
        finest = {r["method"]: r for r in res["rows"]}         # the last row per method
        table = Table(title=f"{name}: interpolation error vs keyframe spacing "
                            f"({res['vertices']} of {res['moving_vertices']} moving vertices; finest spacing "
                            f"{min(r['spacing'] for r in res['rows']):.4g} s)")
        for col in ("method", "order expected", "order measured", "interior", "max err", "rms err",
                    "eval ms/frame", "fit ms"):
            table.add_column(col, justify="right")
        for method, o in res["orders"].items():
            r = finest[method]
            table.add_row(method, str(o["expected"]), f"{o['measured']:.2f}", f"{o['measured_interior']:.2f}",
                          f"{r['max_err']:.2e}", f"{r['rms_err']:.2e}", f"{r['eval_ms']:.3f}", f"{r['build_ms']:.1f}")
        console.print(table)
        sh = res["shipped"]
        console.print(f"  {name} as shipped (its own keys and methods) vs exact motion: max {sh['max_err']:.2e}, "
                      f"rms {sh['rms_err']:.2e}; {sh['interp_ms']:.2f} ms per frame to place all vertices")
    table = Table(title="bounce (velocity jump at each contact): lowest height reached; < 0 = through the floor")
    densities = sorted({r["keys_per_second"] for r in report["bounce"]})
    table.add_column("method")
    for d in densities:
        table.add_column(f"{d} keys/s", justify="right")
    for d in densities:
        table.add_column(f"max err {d}/s", justify="right")
    methods = list(dict.fromkeys(r["method"] for r in report["bounce"]))
    by = {(r["method"], r["keys_per_second"]): r for r in report["bounce"]}
    for m in methods:
        table.add_row(m, *(f"{by[m, d]['min_height']:+.1e}" for d in densities),
                      *(f"{by[m, d]['max_err']:.1e}" for d in densities))
    console.print(table)
    image = report.get("image")
    if image:
        for study, knob in (("spp", "spp"), ("light_samples", "light_samples"), ("motion_blur", "spp")):
            ref = image["ref_light_samples"] if knob == "light_samples" else image["ref_spp"]
            for name, rows in image.get(study, {}).items():
                what = "passes, each at its own shutter time" if study == "motion_blur" else knob.replace("_", " ")
                table = Table(title=f"{name}: image error vs {what} ({image['resolution']}², "
                                    f"against {ref}; slope of log RMSE vs log ms "
                                    f"{image['slopes'][f'{name} ' + study.replace('_', ' ')]:.2f})")
                for col in (knob, "ms/frame", "rays", "RMSE", "max", "PSNR dB"):
                    table.add_column(col, justify="right")
                for r in rows:
                    table.add_row(str(r[knob]), f"{r['ms']:.1f}", f"{r['rays']:,}", f"{r['rmse']:.2e}",
                                  f"{r['max']:.2e}", f"{r['psnr']:.1f}")
                console.print(table)
        for name, rows in image.get("budget", {}).items():
            table = Table(title=f"{name}: error budget (render.max_error) against uniform spp: rays for "
                                f"the same RMSE")
            for col in ("max_error", "ms/frame", "rays", "RMSE", "max", "PSNR dB", "uniform rays", "ray savings"):
                table.add_column(col, justify="right")
            for r in rows:
                same = r["uniform_rays_same_rmse"]
                table.add_row(f"{r['max_error']:g}", f"{r['ms']:.1f}", f"{r['rays']:,}", f"{r['rmse']:.2e}",
                              f"{r['max']:.2e}", f"{r['psnr']:.1f}", f"{same:,.0f}" if same else "out of range",
                              f"{r['ray_savings']:.2f}x" if r["ray_savings"] else "-")
            console.print(table)
        console.print("expected slopes: " + ", ".join(f"{k} {v}" for k, v in image["expected_slopes"].items()))
    precision = report.get("precision")
    if precision:
        table = Table(title=f"{precision['scene']}: float32 hit distance against a float64 brute force, "
                            "scene scaled and moved (relative error; pixels whose hit or miss differs)")
        for col in ("scale", "offset", "median rel", "99% rel", "hit/miss differs"):
            table.add_column(col, justify="right")
        for r in precision["rows"]:
            rel = [f"{r[k]:.1e}" if r[k] is not None else "no common hit" for k in ("median_rel", "p99_rel")]
            table.add_row(f"{r['scale']:g}", f"{r['offset']:g}", *rel, f"{100 * r['hit_mismatch']:.2f}%")
        console.print(table)


def write_report(report, plot_path: Path, json_path: Path):
    """JSON with every row, and one figure: error vs spacing, error vs cost, bounce."""
    import matplotlib
    import matplotlib.ticker
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    json_path.parent.mkdir(parents=True, exist_ok=True)
    json_path.write_text(json.dumps(report, indent=1))
    plot_path.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 5, figsize=(26, 5))
    for name, res in report["scenes"].items():
        for method in res["orders"]:
            rows = [r for r in res["rows"] if r["method"] == method]
            o = res["orders"][method]
            label = f"{name} {method} (p={o['measured']:.1f}, interior {o['measured_interior']:.1f})"
            axes[0].loglog([r["spacing"] for r in rows], [r["max_err"] for r in rows], "o-", label=label)
            axes[1].loglog([r["frame_cost_ms"] for r in rows], [r["max_err"] for r in rows], "o-", label=label)
    axes[0].set(xlabel="key spacing h (s)", ylabel="max vertex error", title="error vs keyframe spacing")
    axes[1].set(xlabel="interpolation ms per frame (fit amortised over a period at 24 fps)",
                ylabel="max vertex error", title="error vs run time")
    axes[0].legend(fontsize=7)
    for ax in axes[:2]:
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    methods = list(dict.fromkeys(r["method"] for r in report["bounce"]))
    densities = sorted({r["keys_per_second"] for r in report["bounce"]})
    width = 0.8 / len(densities)
    for i, d in enumerate(densities):
        vals = [next(r["min_height"] for r in report["bounce"] if r["method"] == m and r["keys_per_second"] == d)
                for m in methods]
        axes[2].bar([j + i * width for j in range(len(methods))], vals, width, label=f"{d} keys/s")
    axes[2].axhline(0, color="k", lw=0.8)
    axes[2].set_xticks([j + 0.4 - width / 2 for j in range(len(methods))], methods, rotation=45)
    axes[2].set(ylabel="lowest height (floor at 0)", title="bounce: through the floor?")
    axes[2].legend(fontsize=7)
    image = report.get("image") or {}
    for study, knob, style in (("spp", "spp", "o-"), ("budget", "budget", "s--"),
                               ("light_samples", "light samples", "^:"), ("motion_blur", "motion blur", "d-.")):
        for name, rows in image.get(study, {}).items():
            key = f"{name} {knob}"
            axes[3].loglog([r["ms"] for r in rows], [r["rmse"] for r in rows], style,
                           label=f"{name}: {knob} (slope {image['slopes'][key]:.2f})")
    axes[3].set(xlabel="ms per frame (expected slopes: -0.5 random, -0.75 stratified)",
                ylabel="image RMSE (linear RGB)", title="image error vs run time")
    for study, style in (("spp", "o-"), ("budget", "s--")):
        for name, rows in image.get(study, {}).items():
            axes[4].loglog([r["rays"] for r in rows], [r["rmse"] for r in rows], style, label=f"{name}: {study}")
    axes[4].set(xlabel="rays per frame (camera + shadow)", ylabel="image RMSE (linear RGB)",
                title="uniform spp and the error budget: error vs rays")
    if image:
        axes[3].legend(fontsize=7)
        axes[4].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(plot_path, dpi=110)
    plt.close(fig)
