"""Progress bar and the per-phase summary table (rich)."""
import contextlib

from rich.console import Console as RichConsole
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn
from rich.table import Table


class Console(RichConsole):
    """rich's Console, except that a reader who stops reading (`| head`)
    raises BrokenPipeError for the command line to handle (cli/main.py)
    instead of rich's own exit 1: the work is done by then."""

    def on_broken_pipe(self):
        raise BrokenPipeError()


@contextlib.contextmanager
def progress(n_frames, show):
    """Yields (on_frame, on_compile) callbacks for render_animation; draws a
    bar only when `show` (a terminal). While a first run compiles, the bar's
    line says so ("compiling (first run only): 7 kernels, now shade_samples,
    41 s"); then it counts frames."""
    if not show:
        yield None, None
        return
    import time
    with Progress(TextColumn("{task.fields[what]}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TextColumn("{task.fields[fps]}"), TimeRemainingColumn(),
                  console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task("render", total=n_frames, fps="", what="frames")
        t0 = []

        def on_frame(row):
            ms = sum(row[k] for k in ("interp_ms", "build_ms", "trace_ms", "shade_ms", "shadow_ms"))
            bar.update(task, advance=1, fps=f"{1000.0 / ms:.1f} fps" if ms > 0 else "")

        def on_compile(watch):
            if watch is None:                      # the warm-up is over
                bar.update(task, what="frames")
                return
            if not t0:
                t0.append(time.perf_counter())
            from anim.render.compile_helper import running
            now = watch.current
            bar.update(task, what=f"compiling (first run only{', two processes' if running else ''}): "
                                  f"{len(watch.done)} kernels"
                                  + (f", now {now.rsplit('.', 1)[-1]}" if now else "")
                                  + f", {time.perf_counter() - t0[0]:.0f} s")
        yield on_frame, on_compile


def fitted_table(title, columns, rows, width, key=()) -> Table:
    """A table that fits `width` columns without cutting a cell: every
    column is at least as wide as its widest cell (headers fold at spaces),
    and while the table is too wide the columns with the lowest keep rank
    are left out (rank None: always kept), said in the caption. rich alone
    shrank cells to "de…" and numbers to "0.…". A column among `key` (the
    headers that say what a row is) stays while leaving it out would make
    two rows read alike there.
    columns: [(header, rank)]; rows: lists of cell strings."""
    natural = [max([len(h)] + [len(r[i]) for r in rows]) for i, (h, _) in enumerate(columns)]
    need = [max([len(w) for w in h.split()] + [len(r[i]) for r in rows]) for i, (h, _) in enumerate(columns)]
    keep = list(range(len(columns)))
    if sum(w + 3 for w in natural) + 1 <= width:
        need = natural                   # room for every header on one line
    dropped = []
    droppable = sorted((rank, i) for i, (_, rank) in enumerate(columns) if rank is not None)
    key_at = [i for i, (h, _) in enumerate(columns) if h in key]

    def tells_rows_apart(i):
        rest = [j for j in key_at if j in keep and j != i]
        return len({tuple(r[j] for j in rest) for r in rows}) < len({tuple(r[j] for j in rest + [i]) for r in rows})
    while sum(need[i] + 3 for i in keep) + 1 > width and droppable:
        _, i = droppable.pop(0)
        if i in key_at and tells_rows_apart(i):
            continue
        keep.remove(i)
        dropped.append(columns[i][0])
    table = Table(title=title, caption=(f"narrow terminal: {', '.join(dropped)} left out (a wider terminal "
                                        "or --json shows them)") if dropped else None)
    for i in keep:
        table.add_column(columns[i][0], justify="right", width=need[i], overflow="fold")
    for r in rows:
        table.add_row(*(r[i] for i in keep))
    return table


def summary_table(stats):
    s = stats["summary"]
    run = stats["runs"][-1] if stats.get("runs") else {}
    compiled = {**(run.get("compiled_by_helper") or {}), **(run.get("compiled") or {})}
    med = s["median_ms"]
    table = Table(title=f"{stats['scene']}  {stats['resolution'][0]}x{stats['resolution'][1]}  "
                        f"{stats.get('accel', '')}  packet {stats['packet']}  threads {stats['threads']}  "
                        f"{len(stats['frames'])} frames (median ms per frame)")
    for col in ("interp", "build", "trace", "shade", "shadow", "write"):
        table.add_column(col, justify="right")
    table.add_row(*("-" if med[k + "_ms"] is None else f"{med[k + '_ms']:.2f}"
                    for k in ("interp", "build", "trace", "shade", "shadow", "write")))
    console = Console()
    console.print(table)
    if stats.get("accel_choice"):
        console.print(f"camera rays: {stats['accel_choice']}")
    if s.get("peak_rss_bytes"):
        per_tri = s.get("bytes_per_triangle")
        console.print(f"peak RSS {s['peak_rss_bytes'] / 1024 ** 3:.2f} GB"
                      + (f" ({per_tri:,.0f} bytes a triangle beyond the process before the scene and the keyframes)"
                         if per_tri is not None else ""))
    warm = s.get("warm_up_s", s["compile_s"])
    console.print(f"fps_raycast {s['fps_raycast']:.1f}   fps_full {s['fps_full']:.1f}   "
                  f"fps_wall {s['fps_wall']:.1f}   warm-up {warm:.2f} s (not in fps; "
                  + (f"{len(compiled)} kernels compiled in {s['compile_s']:.2f} s"
                     + (" and a helper process" if run.get("compiled_by_helper") else "") + ", cached for later runs)"
                     if compiled else "every kernel from the cache; the structures built for frame 0)"))


def bench_table(rows, console=None):
    """One line per scene and packet size (and peer); the fastest fps_raycast
    per scene marked; with peers, frustrace's fps_full over the best peer's."""
    with_peers = any("vs_best_peer" in r for r in rows)
    # (header, keep rank: the lowest goes first on a narrow terminal; None = always)
    columns = [("scene", None), ("accel", None), ("shadows", 9), ("tris", 3), ("res", 2), ("packet", 8),
               ("threads", 1), ("interp", 4), ("build", 6), ("trace", None), ("shade", None), ("shadow", None),
               ("write", 5), ("fps_raycast", 10), ("fps_full", None), ("Mrays/s", 11), ("shadow Mrays/s", 7),
               ("tests/ray", 0), *([("full / best peer", None)] if with_peers else [])]
    best = {}
    for r in rows:
        if r["fps_raycast"] > best.get(r["scene"], (0, None))[0]:
            best[r["scene"]] = (r["fps_raycast"], (r["accel"], r.get("shadow_accel"), r["packet"]))
    cells = []
    for r in rows:
        mark = " *" if best[r["scene"]][1] == (r["accel"], r.get("shadow_accel"), r["packet"]) else ""
        peer = r.get("peer", False)
        ratio = [f"{r['vs_best_peer']:.2f}x" if "vs_best_peer" in r else "-"] if with_peers else []
        cells.append([r["scene"], r["accel"], r.get("shadow_accel", "-"), str(r["triangles"]), str(r["resolution"]),
                      ("-" if peer else str(r["packet"])) + mark,
                      str(r["threads"]), f"{r['interp_ms']:.2f}", f"{r['build_ms']:.2f}", f"{r['trace_ms']:.1f}",
                      f"{r['shade_ms']:.1f}", f"{r['shadow_ms']:.1f}", f"{r['write_ms']:.1f}",
                      f"{r['fps_raycast']:.1f}", f"{r['fps_full']:.1f}", f"{r['mrays_per_s']:.1f}",
                      f"{r['shadow_mrays_per_s']:.1f}",
                      "-" if peer else f"{r['tri_tests'] / max(r['resolution'] ** 2, 1):.1f}", *ratio])
    if console is None:
        console = Console()
        if not console.is_terminal:
            console = Console(width=210)  # a pipe or file gets the whole table
    console.print(fitted_table("frustrace bench (median ms per frame; compile time excluded)", columns, cells,
                               console.width, key=("scene", "accel", "shadows", "res", "packet", "threads")))
    # the BVH's figures once a scene (its rows of other packets build the same trees)
    bvh = list({r["scene"]: r for r in reversed([r for r in rows if "bvh_build_ms" in r])}.values())[::-1]
    for r in bvh:
        console.print(f"{r['scene']}: BVH build {r['bvh_build_ms']:.2f} ms ({r['bvh_build_ms_per_100k']:.2f} "
                      f"per 100K triangles), refit {r['bvh_refit_ms']:.2f} ms of "
                      f"{r['moving_triangles']:,} moving triangles ({r['bvh_refit_ms_per_100k']:.2f} per 100K); "
                      f"{r['bvh_rebuilds']} rebuilds, SAH growth up to {r['bvh_max_sah_growth']:.2f}x")
    if any(r.get("peer") for r in rows):
        console.print("peers: structure rebuilt every frame, one shadow ray per hit and light; no shading "
                      "(shade 0) and rays made before the clock starts, both in their favour")


def scale_table(result, console=None):
    """bench --scale: a row per size (frustrace's phases, Embree's, memory),
    then each phase's growth exponent."""
    columns = [("triangles", None), ("accel", 2), ("interp", 3), ("build", None), ("trace", None),
               ("shade", None), ("shadow", None), ("frame", None), ("frame 0 warm-up s", 1),
               ("peak RSS GB", None), ("bytes/tri", None), ("Embree build/trace/shadow", 0)]
    cells = []
    for r in result["rows"]:
        e = r.get("embree")
        cells.append([f"{r['triangles']:,}", r["accel"], f"{r['interp_ms']:.1f}", f"{r['build_ms']:.1f}",
                      f"{r['trace_ms']:.1f}", f"{r['shade_ms']:.1f}", f"{r['shadow_ms']:.1f}",
                      f"{r['frame_ms']:.1f}", f"{r['warm_up_s']:.1f}", f"{r['peak_rss_gb']:.2f}",
                      f"{r['bytes_per_triangle']:.0f}",
                      f"{e['build_ms']:.0f}/{e['trace_ms']:.0f}/{e['shadow_ms']:.0f}" if e else "-"])
    g = result["growth"]
    cells.append(["growth exponent", "", *(f"{g[k]:.2f}" if g[k] is not None else "-"
                                           for k in ("interp_ms", "build_ms", "trace_ms", "shade_ms", "shadow_ms",
                                                     "frame_ms")), "", "", "",
                  "/".join(f"{v:.2f}" if v is not None else "-" for v in result.get("embree_growth", {}).values())
                  or "-"])
    console = console or (Console() if Console().is_terminal else Console(width=190))
    console.print(fitted_table(f"frustrace bench --scale ({result['resolution']}^2, {result['frames']} frames, "
                               "median ms a frame; bytes/tri: peak RSS beyond the interpreter and the keyframes)",
                               columns, cells, console.width, key=("triangles",)))


def instances_table(result, console=None):
    """bench --instances: a row per count (two-level phases, memory, the
    flattened world's frame where it was measured), then the growth."""
    columns = [("instances", None), ("triangles", 2), ("interp", 3), ("build", None), ("trace", None),
               ("shade", None), ("shadow", None), ("frame", None), ("frame 0 warm-up s", 1),
               ("peak RSS GB", None), ("flattened: frame / build / peak RSS GB", 0)]
    cells = []
    for r in result["rows"]:
        f = r.get("flat")
        cells.append([f"{r['instances']:,}", f"{r['triangles']:,}", f"{r['interp_ms']:.1f}", f"{r['build_ms']:.1f}",
                      f"{r['trace_ms']:.1f}", f"{r['shade_ms']:.1f}", f"{r['shadow_ms']:.1f}",
                      f"{r['frame_ms']:.1f}", f"{r['warm_up_s']:.1f}", f"{r['peak_rss_gb']:.2f}",
                      f"{f['frame_ms']:.0f} / {f['build_ms']:.0f} / {f['peak_rss_gb']:.2f}" if f else "-"])
    g = result["growth"]
    cells.append(["growth exponent", "", *(f"{g[k]:.2f}" if g[k] is not None else "-"
                                           for k in ("interp_ms", "build_ms", "trace_ms", "shade_ms", "shadow_ms",
                                                     "frame_ms")), "", "", ""])
    per = result.get("bytes_per_instance")
    console = console or (Console() if Console().is_terminal else Console(width=190))
    console.print(fitted_table(f"frustrace bench --instances ({result['resolution']}^2, {result['frames']} frames, "
                               "median ms a frame, two-level"
                               + (f"; {per:,.0f} bytes of peak RSS an instance" if per is not None else "") + ")",
                               columns, cells, console.width, key=("instances",)))


def compare_table(result, console=None):
    """One row per structure, then the image differences against the first."""
    rows = result["rows"]
    r0 = rows[0]
    title = (f"frustrace compare: {result['scene']}  {r0['triangles']} triangles  "
             f"{r0['resolution'][0]}x{r0['resolution'][1]}  {r0['frames']} frames  "
             f"{result.get('threads', '?')} threads (medians per frame); shadow rays of every row through "
             f"the {result.get('shadow_accel', '?')}")
    columns = [("structure", None), ("packet", 3), ("build ms", None), ("trace ms", None), ("shadow ms", None),
               ("fps_raycast", None), ("fps_full", None), ("primary tests", 4), ("all tests", 2),
               ("cells/nodes per packet", 1), ("published tests", 0)]
    cells = []
    for r in rows:
        pub = f"{r['published_tests'] / 1e6:.2f}M" if r["published_tests"] else "-"
        cells.append([r["structure"], f"{r['packet']}²", f"{r['build_ms']:.2f}", f"{r['trace_ms']:.1f}",
                      f"{r['shadow_ms']:.1f}", f"{r['fps_raycast']:.1f}", f"{r['fps_full']:.1f}",
                      f"{r['primary_tests'] / 1e6:.2f}M", f"{r['tri_tests'] / 1e6:.1f}M",
                      f"{r['visits_per_packet']:.1f}", pub])
    console = console or (Console() if Console().is_terminal else Console(width=170))
    console.print(fitted_table(title, columns, cells, console.width))
    for d in result["diff"]:
        console.print(f"{d['b']} vs {d['a']}: {d['hit_mismatch_pixels']} pixels hit/miss differ, "
                      f"depth max rel diff {d['max_rel_depth_diff']:.2e} "
                      f"({d['pixels_depth_diff_over_1e-5']} pixels over 1e-5), "
                      f"max RGBA diff {d['max_rgba_diff']:.3g} ({d['pixels_rgba_diff_over_1e-2']} pixels over 0.01)")
    console.print("published tests: Wald et al. 2006 (Coherent Grid Traversal), per frame, for reference; "
                  "their scenes and resolution differ")
