"""`frustrace bench --plot`: median ms per phase as stacked bars."""
from pathlib import Path

PHASES = ("interp", "build", "trace", "shade", "shadow", "write")


def plot_phases(rows, path: Path):
    """Stacked bars of median ms per phase, one bar per scene and setting,
    grouped by scene (peers' bars beside frustrace's)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    x, group_x = [], {}
    for i, r in enumerate(rows):                 # a gap of one bar between scenes
        x.append(i + scenes.index(r["scene"]))
        group_x.setdefault(r["scene"], []).append(x[-1])
    labels = [r["accel"] + ("" if r.get("peer") else f" {r['packet']}"
                            + (f" /{r['shadow_accel']}" if r.get("shadow_accel") else "")) for r in rows]
    fig, ax = plt.subplots(figsize=(max(6.0, 0.42 * (x[-1] + 1) + 1.5) if rows else 6.0, 5.0))
    bottom = [0.0] * len(rows)
    for phase in PHASES:
        vals = [r.get(f"{phase}_ms", 0.0) for r in rows]
        ax.bar(x, vals, bottom=bottom, label=phase, width=0.85)
        bottom = [b + v for b, v in zip(bottom, vals)]
    ax.set_xticks(x, labels, rotation=90, fontsize=8)
    for name, xs in group_x.items():
        ax.text(sum(xs) / len(xs), 1.0, name, transform=ax.get_xaxis_transform(), ha="center",
                va="bottom", fontsize=9, weight="bold")
    ax.set_ylabel("ms per frame (median)")
    res = rows[0]["resolution"] if rows else 0
    ax.set_title(f"frustrace bench: {res}x{res}, {rows[0]['threads'] if rows else 0} threads", pad=18)
    ax.legend(ncol=len(PHASES), fontsize=8, loc="upper left", bbox_to_anchor=(0, -0.28))
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_scale(result, path: Path):
    """bench --scale: ms a frame per phase against triangles, log-log, with
    Embree's build, trace and shadow rays dashed beside them."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = result["rows"]
    n = [r["triangles"] for r in rows]
    fig, ax = plt.subplots(figsize=(7.0, 5.0))
    for key in ("build_ms", "trace_ms", "shade_ms", "shadow_ms", "frame_ms"):
        g = result["growth"].get(key)
        ax.loglog(n, [max(r[key], 1e-3) for r in rows], "o-",
                  label=f"frustrace {key[:-3]}" + (f" (n^{g:.2f})" if g is not None else ""))
    embree = [(r["triangles"], r["embree"]) for r in rows if r.get("embree")]
    for key in ("build_ms", "trace_ms", "shadow_ms"):
        if embree:
            ax.loglog([t for t, _ in embree], [max(e[key], 1e-3) for _, e in embree], "x--",
                      label=f"Embree {key[:-3]}")
    ax.set_xlabel("triangles")
    ax.set_ylabel("ms per frame (median)")
    ax.set_title(f"frustrace bench --scale: {result['resolution']}x{result['resolution']}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
