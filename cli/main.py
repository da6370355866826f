"""`frustrace` command line (../shared/SPEC.md section 1).

Exit codes: 0 success, 2 bad input (one line naming file, key and problem),
1 internal error.
"""
import atexit
import os
import signal
import sys
import threading
import warnings
from pathlib import Path

import click

import raycore
from anim.errors import SceneError
from raycore.config import ACCELS, PACKET_SIZES


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread so that a render ends as on Ctrl-C."""


class StopRequest:
    """Signal handler for Ctrl-C and SIGTERM during a render: the first one
    is noted and the render loop stops between frames (the frame being
    written is finished); a second one stops at once. An exception raised
    from a handler inside a numba call arrives wrapped in a SystemError,
    so the first one is not raised there."""

    def __init__(self):
        self.signum = None

    def __call__(self, signum, frame):
        if self.signum is not None:
            raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()
        self.signum = signum

    def pending(self):
        """The exception to end the render with, or None."""
        if self.signum is None:
            return None
        return Terminated() if self.signum == signal.SIGTERM else KeyboardInterrupt()


def _on_sigterm(signum, frame):
    raise Terminated()


def _interrupt_in(exc):
    """The KeyboardInterrupt behind exc (itself, or the cause of a SystemError
    from a signal that arrived inside a numba call), else None."""
    while exc is not None:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        exc = exc.__cause__ or exc.__context__
    return None


def _one_line(self, file=None):
    """click's usage errors in one line, as frustrace's own errors (click
    prints Usage, Try, a blank line and Error: four lines)."""
    where = f"; see '{self.ctx.command_path} --help'" if self.ctx is not None else ""
    click.echo(f"frustrace: error: {self.format_message().rstrip('.')}{where}", err=True)


click.UsageError.show = _one_line


class Group(click.Group):
    """Turns SceneError into one line on stderr and exit code 2; Ctrl-C into
    exit 130 and SIGTERM into 143 after the render loop has cleaned up; an
    I/O fault writing a frame into one line and exit 1."""

    def invoke(self, ctx):
        from anim.render.job import FrameRenderError, FrameWriteError
        main_thread = threading.current_thread() is threading.main_thread()
        before = signal.signal(signal.SIGTERM, _on_sigterm) if main_thread else None
        try:
            # libraries' own warnings (numpy overflow notes, pygltflib's "ignoring
            # chunk") are not for users: frustrace's warnings go through click.echo
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return super().invoke(ctx)
        except SceneError as exc:
            click.echo(f"frustrace: error: {exc}", err=True)
            sys.exit(2)
        except (click.exceptions.Exit, click.ClickException, click.Abort, SystemExit):
            raise
        except (KeyboardInterrupt, SystemError) as caught:
            exc = _interrupt_in(caught)
            if exc is None:
                return self._internal_error(caught)
            what = "terminated" if isinstance(exc, Terminated) else "interrupted"
            stats_path = ctx.meta.get("frustrace.stats_path")
            if ctx.invoked_subcommand == "render" and stats_path is not None and Path(stats_path).exists():
                what += (f"; every frame written is complete and listed in {stats_path}, "
                         "none is half-written (--resume renders the rest)")
            elif ctx.invoked_subcommand == "render":
                what += " before any frame was rendered; nothing was written"
            click.echo(f"frustrace: {what}", err=True)
            sys.exit(143 if isinstance(exc, Terminated) else 130)
        except (FrameWriteError, FrameRenderError) as exc:
            click.echo(f"frustrace: error: {exc}; the frames before it are complete", err=True)
            sys.exit(1)
        except BrokenPipeError:
            # the reader of our output went away (`render ... | head -1`): the work
            # is done, only its report was cut short; keep Python from failing on exit
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            sys.exit(0)
        except Exception as exc:                      # internal error: exit 1
            self._internal_error(exc)
        finally:
            if main_thread:
                signal.signal(signal.SIGTERM, before)

    @staticmethod
    def _internal_error(exc):
        if os.environ.get("FRUSTRACE_DEBUG"):
            raise exc
        click.echo(f"frustrace: internal error: {type(exc).__name__}: {exc} "
                   "(set FRUSTRACE_DEBUG=1 for a traceback)", err=True)
        sys.exit(1)


@click.group(cls=Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(raycore.__version__, prog_name="frustrace")
def main():
    """frustrace: a frustum-packet ray caster for keyframed mesh animations.

    Each frame: interpolate vertices, rebuild a uniform grid, trace NxN ray
    packets with Coherent Grid Traversal, shade with shadows, write OpenEXR.
    """


def load_scene(path, camera=None, instancing=None):
    """AnimatedScene of path (a scene file, a USD stage or an FBX file), its warnings
    printed on stderr."""
    from anim.scene import AnimatedScene
    scene = AnimatedScene(path, camera, instancing)
    for message in scene.warnings:
        click.echo(f"frustrace: warning: {message}", err=True)
    return scene


def _accel_list(text, hint):
    """'grid, bvh' -> ['grid', 'bvh'], each one of ACCELS."""
    names = [a.strip() for a in text.split(",") if a.strip()]
    if not names or any(a not in ACCELS for a in names):
        raise click.BadParameter(f"comma-separated {', '.join(ACCELS)}", param_hint=hint)
    return names


def _finite(value, hint):
    """value, unless it is NaN (which every range check lets through)."""
    if value is not None and value != value:
        raise click.BadParameter("must be a number, got nan", param_hint=hint)
    return value


def _resolution(text):
    """'320x240' -> (320, 240); None stays None."""
    if text is None:
        return None
    w, sep, h = text.lower().partition("x")
    try:
        size = (int(w), int(h))
    except ValueError:
        size = None
    if not sep or size is None or not all(0 < v <= 16384 for v in size):
        raise click.BadParameter(f"expected WxH with 1..16384 each, got {text!r}", param_hint="--res")
    return size


def _aovs(text):
    """--aov N,P,id as a tuple, or None when not given."""
    if text is None:
        return None
    names = tuple(dict.fromkeys(n.strip() for n in text.split(",") if n.strip()))
    unknown = [n for n in names if n not in ("N", "P", "id")]
    if unknown or not names:
        raise click.BadParameter(f"{', '.join(unknown) or text!r}: the AOVs are N, P and id", param_hint="--aov")
    return names


def parse_frames(text, scene):
    if text is None:
        return scene.frame_numbers
    try:
        a, _, b = text.partition(":")
        start = int(a) if a else scene.spec.frames.start
        end = int(b) if b else (start if not _ else scene.spec.frames.end)
    except ValueError:
        raise click.BadParameter(f"expected A:B (frame numbers), got {text!r}", param_hint="--frames")
    if end < start:
        raise click.BadParameter(f"end {end} is before start {start}", param_hint="--frames")
    from anim.schema import MAX_FRAMES
    if end - start >= MAX_FRAMES:
        raise click.BadParameter(f"{end - start + 1:,} frames; at most {MAX_FRAMES:,}", param_hint="--frames")
    return range(start, end + 1)


CAMERA_HELP = ("For a USD stage: the camera prim to look through (default: the stage's first camera); "
               "for an FBX file: the camera's node name.")


@main.command()
@click.argument("anim_yaml", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--camera", metavar="PRIM", help=CAMERA_HELP)
@click.option("-o", "--out-dir", type=click.Path(file_okay=False, path_type=Path),
              help="Directory for the frames (default: output.path of the scene, relative to it).")
@click.option("--frames", "frames_text", metavar="A:B", help="Render frames A to B inclusive (default: all of frames.start..end).")
@click.option("--accel", type=click.Choice(("auto", *ACCELS)), help="Acceleration structure of the camera rays: auto (chosen by the scene's triangles per pixel, as measured), the per-frame uniform grid, an SAH kd-tree with frustum traversal, or the per-frame BVH (default: render.accel, auto).")
@click.option("--shadow-accel", type=click.Choice(ACCELS), help="Acceleration structure of the shadow rays (default: render.shadow_accel, else bvh, measured fastest).")
@click.option("--packet", type=click.Choice([str(p) for p in PACKET_SIZES]), help="Primary-ray packet size N of the grid (NxN rays per frustum; default: render.packet, else 32). The kd-tree and the BVH always use 8x8.")
@click.option("--threads", type=click.IntRange(0, 1024), default=0, show_default=True, help="Render threads; 0 = all cores.")
@click.option("--no-shadows", is_flag=True, help="Skip shadow rays (overrides render.shadows).")
@click.option("--spp", type=click.IntRange(1, 1024), help="Samples per pixel (default: render.spp, 1 if unset); 1 = the pixel-centre ray.")
@click.option("--max-error", type=click.FloatRange(0, 1), metavar="E", callback=lambda ctx, param, v: _finite(v, "--max-error"),
              help="Error budget per pixel in linear RGBA (default: render.max_error, 0 = off): start at the "
                   "pixel centre and give more samples, up to --spp (64 when spp is 1), only to pixels "
                   "whose estimated error is above E.")
@click.option("--shutter", type=click.FloatRange(0, 1000), metavar="S", callback=lambda ctx, param, v: _finite(v, "--shutter"),
              help="Motion blur: the shutter is open S frame intervals (default: render.motion_blur.shutter, "
                   "0 = off; 0.5 = a 180-degree shutter). Each of the --spp passes takes one time in it.")
@click.option("--aov", "aovs", metavar="N,P,id", callback=lambda ctx, param, v: _aovs(v),
              help="Extra EXR channels, as output.aovs (default: output.aovs, none for a USD stage or FBX file): "
                   "N (smooth normal), P (position), id (triangle index).")
@click.option("--stats", "stats_path", type=click.Path(dir_okay=False, path_type=Path), help="Where to write stats.json (default: next to the frames); merged with an earlier run's by frame number.")
@click.option("--resume", is_flag=True, help="Skip frames already written whole (a truncated or foreign file is rendered again); "
                                            "--resume renders into one directory share the frames.")
@click.option("--overwrite", is_flag=True, help="Replace frames that already exist.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar and no summary table.")
@click.option("--res", callback=lambda ctx, param, v: _resolution(v), metavar="WxH",
              help="Render at W x H instead of output.resolution (a quick preview; the camera's "
                   "field of view is kept vertically).")
@click.option("--preview", "preview_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Also write the frames as one animated .gif or .webp (tone-mapped, at most 640 px) "
                   "to look at.")
@click.option("--workers", type=click.IntRange(1, 1024), metavar="N",
              help="Render on an embedded Dask LocalCluster of N worker processes on this machine "
                   "(listening on 127.0.0.1 only); each uses cores / N threads unless --threads says.")
@click.option("--scheduler", metavar="ADDRESS",
              help="Render on an existing Dask cluster: tcp://HOST:PORT, tls://HOST:PORT or a scheduler "
                   "JSON file. The scene and its files are sent to the workers; they need only frustrace.")
@click.option("--chunk", type=click.IntRange(1, 100000), default=4, show_default=True,
              help="With --workers or --scheduler: consecutive frames per task (a worker keeps the "
                   "static grid from frame to frame; 4 measured fastest of 1, 4 and 12 on hand at 1024^2).")
@click.option("--tls-ca", type=click.Path(dir_okay=False, path_type=Path), help="CA certificate for tls:// (PEM).")
@click.option("--tls-cert", type=click.Path(dir_okay=False, path_type=Path), help="Client certificate for tls:// (PEM).")
@click.option("--tls-key", type=click.Path(dir_okay=False, path_type=Path), help="Client key for tls:// (PEM).")
@click.option("--instancing", type=click.Choice(("auto", "flatten", "two_level")),
              help="Instances (instances:, USD point instancers): copied into the frame's triangles (flatten), "
                   "or traced as a prototype's tree per instance under a top level (two_level); auto: two-level "
                   "from 3M copied triangles on, 1M for prototypes of 1,000 or more (default: render.instancing, auto).")
def render(anim_yaml, camera, out_dir, frames_text, stats_path, resume, overwrite, quiet, preview_path, workers,
           scheduler, chunk, tls_ca, tls_cert, tls_key, instancing, **settings):
    """Render ANIM_YAML (a scene file, a USD stage: .usd, .usda, .usdc,
    .usdz, or an FBX file) to one OpenEXR file per frame, plus stats.json."""
    if resume and overwrite:
        raise click.UsageError("--resume and --overwrite exclude each other")
    if workers and scheduler:
        raise click.UsageError("--workers and --scheduler exclude each other")
    from anim.render.frame_files import frames_dir
    from anim.render.job import RenderJob, render_animation
    from anim.render.settings import render_config

    from cli.report import progress, summary_table

    scene = load_scene(anim_yaml, camera, instancing)
    spec = scene.spec
    frames = parse_frames(frames_text, scene)
    scene.check_camera(frames)                 # frames outside the file's range too
    if frames_text is not None:                # the scene's own range was checked as it loaded
        for note in scene.keys_outside(frames[0], frames[-1]):
            click.echo(f"frustrace: warning: {note}", err=True)
    if not (workers or scheduler):
        ctx = click.get_current_context()
        given = [name for name, param in (("--chunk", "chunk"), ("--tls-ca", "tls_ca"), ("--tls-cert", "tls_cert"),
                                          ("--tls-key", "tls_key"))
                 if ctx.get_parameter_source(param) not in (None, click.core.ParameterSource.DEFAULT)]
        if given:
            click.echo(f"frustrace: warning: {', '.join(given)} {'is' if len(given) == 1 else 'are'} for "
                       "--workers or --scheduler; this render runs in this process", err=True)
    cfg, notes = render_config(scene, workers=workers, scheduler=scheduler, **settings)
    for note in notes:
        click.echo(f"frustrace: warning: {note}", err=True)
    stats_path = stats_path or frames_dir(scene, out_dir, frames[0]) / "stats.json"
    job = RenderJob(scene, cfg, frames, out_dir, stats_path, resume, overwrite, chunk)
    show = not quiet and sys.stderr.isatty()
    if preview_path:
        from anim.render.paths import writable_file

        from cli.preview import FORMATS
        writable_file(preview_path, "the --preview animation", FORMATS)
    client = cluster = None
    if workers or scheduler:
        from anim.render.cluster import bundle_scene, connect, security_of
        bundle_scene(scene)                # a file that cannot travel is an error before any cluster starts
        client, cluster = connect(scheduler, workers, security=security_of(tls_ca, tls_cert, tls_key))
    click.get_current_context().meta["frustrace.stats_path"] = job.stats_path    # for the interrupt message
    stop = StopRequest()
    before = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with progress(len(frames), show) as (on_frame, on_compile):
            stats = render_animation(job, on_frame, warn=lambda m: click.echo(f"frustrace: warning: {m}", err=True),
                                     should_stop=stop.pending, client=client, on_compile=on_compile)
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)
        if client is not None:             # cancels what is left; the local cluster's workers end
            client.close()
            if cluster is not None:
                cluster.close()
    if preview_path:
        from anim.render.frame_files import frame_file

        from cli.preview import write_animation
        n = write_animation([frame_file(scene, out_dir, f) for f in frames], preview_path, spec.frames.fps)
        if not quiet:
            click.echo(f"wrote {preview_path} ({n} frames)")
    if not quiet:
        if stats["runs"][-1]["frames_rendered"] == 0:
            click.echo(f"nothing to render: all {len(frames)} frames exist and are whole")
        summary_table(stats)


PLOT_FORMATS = (".png", ".pdf", ".svg")


def _bench_scale(sizes_text, res, n_frames, threads, accel, json_path, plot_path):
    """bench --scale: the sizes one after another, a line each as it ends."""
    import json
    import tempfile

    from anim.measure.scale import run_scale

    from cli.report import scale_table
    try:
        sizes = [int(float(s)) for s in sizes_text.split(",") if s.strip()]
    except ValueError:
        raise click.BadParameter(f"comma-separated triangle counts, got {sizes_text!r}", param_hint="--scale-sizes")
    if not sizes or min(sizes) < 100:
        raise click.BadParameter("at least one size, each of 100 triangles or more", param_hint="--scale-sizes")
    if accel is not None and accel not in ACCELS:
        raise click.BadParameter(f"with --scale, one of {', '.join(ACCELS)}", param_hint="--accel")
    with tempfile.TemporaryDirectory(prefix="frustrace-scale-") as tmp:
        result = run_scale(sorted(sizes), res, n_frames, threads, Path(tmp), accel,
                           on_size=lambda row: click.echo(f"bench --scale: {row['triangles']:,} triangles, "
                                                          f"{row['frame_ms']:.1f} ms a frame", err=True))
    result.update({"resolution": res, "frames": n_frames, "threads": threads})
    scale_table(result)
    if json_path:
        json_path.write_text(json.dumps(result, indent=1))
    if plot_path:
        from cli.bench import plot_scale
        plot_scale(result, plot_path)
        click.echo(f"wrote {plot_path}")


def _bench_instances(counts_text, res, n_frames, threads, json_path):
    """bench --instances: the counts one after another, a line each as it ends."""
    import json
    import tempfile

    from anim.measure.instanced import run_instances

    from cli.report import instances_table
    counts = _int_list(counts_text, "--instances")
    if min(counts) < 1:
        raise click.BadParameter("counts of one instance or more", param_hint="--instances")
    with tempfile.TemporaryDirectory(prefix="frustrace-instances-") as tmp:
        result = run_instances(sorted(counts), res, n_frames, threads, Path(tmp),
                               on_count=lambda row: click.echo(f"bench --instances: {row['instances']:,} copies, "
                                                               f"{row['frame_ms']:.1f} ms a frame", err=True))
    result.update({"resolution": res, "frames": n_frames, "threads": threads})
    instances_table(result)
    if json_path:
        json_path.write_text(json.dumps(result, indent=1))


def _int_list(text, name, allowed=None):
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise click.BadParameter(f"expected comma-separated integers, got {text!r}", param_hint=name)
    bad = [v for v in values if allowed and v not in allowed]
    if bad or not values:
        raise click.BadParameter(f"allowed: {', '.join(map(str, allowed))}", param_hint=name)
    return values


@main.command()
@click.option("--scene", "scenes", default="all", show_default=True,
              help="Built-in scenes or scene files (anim.yaml), comma-separated, or 'all': demo, hand, runner, "
                   "toys, marbles, fairy, torus.")
@click.option("--res", type=click.IntRange(16, 8192), help="Image size N (NxN); default 1024, and 192 for the "
                                                           "image error study of --error.")
@click.option("--frames", "n_frames", type=click.IntRange(1, 10000), default=12, show_default=True,
              help="Frames per configuration (medians are reported; two warm-up frames come first).")
@click.option("--accel", default="grid", show_default=True, help="Acceleration structures of the camera rays, comma-separated: grid, kdtree, bvh.")
@click.option("--shadow-accel", "shadow_accels", default="bvh", show_default=True,
              help="Acceleration structures of the shadow rays, comma-separated: grid, kdtree, bvh (a row for each).")
@click.option("--packet", "packets", default="8,16,32", show_default=True, help="Packet sizes to compare, comma-separated.")
@click.option("--threads", type=click.IntRange(0, 1024), default=0, show_default=True, help="Threads; 0 = all cores.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the rows as JSON (with --error: the error report).")
@click.option("--error", "error_report", is_flag=True,
              help="Instead of fps, three studies of error against run time (minutes at the defaults; "
                   "a line per step): interpolation error for every method and key spacing on the built-in "
                   "scenes that know their exact motion, plus a bouncing-ball stiff case; image error of spp, "
                   "the error budget and area-light samples against a 256-spp reference at --res (default "
                   "192); float precision against float64. Prints tables, writes a JSON and a log-log plot. "
                   "Quick variant: --quick --scene torus --res 64.")
@click.option("--quick", is_flag=True,
              help="With --error: fewer key spacings, samples, budgets and precision cases and a 64-spp "
                   "reference: the same tables in a fraction of the time.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              help="A PNG: stacked bars of median ms per phase (interp, build, trace, shade, shadow, "
                   "write) per scene; with --error, the error plot (default interp_error.png; the JSON "
                   "goes next to it unless --json is given).")
@click.option("--peers", is_flag=True,
              help="Also run the same frames through the ray casters of other Python packages that "
                   "are installed (embreex, Open3D, Mitsuba 3: pip install 'frustrace[peers]'), "
                   "rebuilt every frame, one shadow ray per hit and light; adds their rows and "
                   "frustrace's fps_full over the best peer's.")
@click.option("--scale", "scale", is_flag=True,
              help="Instead of the scenes: frame cost by phase and peak memory of a generated deforming mesh "
                   "at --scale-sizes triangles, Embree beside it where embreex is installed, and each "
                   "phase's growth exponent (minutes at a million triangles and more).")
@click.option("--scale-sizes", default="100000,300000,1000000", show_default=True, metavar="N,N,..",
              help="With --scale: the mesh sizes in triangles.")
@click.option("--instances", "instance_counts", metavar="N,N,..",
              help="Instead of the scenes: frame cost by phase and peak memory of N copies of a "
                   "10,000-triangle prototype traced two-level (100000: a billion triangles), the same "
                   "world flattened beside it up to 20M triangles (e.g. 1000,10000,100000).")
def bench(scenes, res, n_frames, accel, shadow_accels, packets, threads, json_path, error_report, quick, plot_path,
          peers, scale, scale_sizes, instance_counts):
    """Measure fps per phase (interp, build, trace, shade, shadow, write) on built-in scenes,
    or with --error the interpolation error against run time."""
    import json

    from anim.measure.bench import SCENE_NAMES, run_bench
    from anim.render.paths import writable_file
    from raycore.jit.presets import set_threads

    from cli.report import bench_table
    res = res if res else (None if error_report else 1024)
    names = list(SCENE_NAMES) if scenes == "all" else [s.strip() for s in scenes.split(",") if s.strip()]
    if not names:
        raise click.BadParameter(f"no scene given; built-in: {', '.join(SCENE_NAMES)}, or a scene file",
                                 param_hint="--scene")
    unknown = [n for n in names if n not in SCENE_NAMES and not Path(n).is_file()]
    if unknown:
        raise click.BadParameter(f"unknown scene {unknown[0]!r} (not built-in, not a file); built-in: "
                                 f"{', '.join(SCENE_NAMES)}", param_hint="--scene")
    for n in names:
        if n not in SCENE_NAMES:
            load_scene(n)                 # a scene file's mistakes: one line, exit 2, before any work
    if json_path:
        writable_file(json_path, "the --json file")
    if plot_path:
        writable_file(plot_path, "the --plot image", PLOT_FORMATS)
    if scale:
        return _bench_scale(scale_sizes, res or 1024, n_frames, threads, accel if accel != "grid" else None,
                            json_path, plot_path)
    if instance_counts:
        return _bench_instances(instance_counts, res or 1024, n_frames, threads, json_path)
    if error_report:
        from anim.measure.error_study import run_error_report
        from anim.measure.image_error import RES as IMAGE_STUDY_RES

        from cli.error_bench import print_report, write_report
        from anim import builtin
        if not any(n in builtin.SCENES for n in names):     # before minutes of work, not after
            raise click.BadParameter(f"none of these scenes knows its exact motion; --error takes "
                                     f"{', '.join(builtin.SCENES)}", param_hint="--scene")
        plot_path = writable_file(plot_path or Path("interp_error.png"), "the --plot image", PLOT_FORMATS)
        json_path = writable_file(json_path or plot_path.with_suffix(".json"), "the --json file")
        report = run_error_report(names, res or IMAGE_STUDY_RES,
                                  say=lambda text: click.echo(f"bench --error: {text}", err=True), quick=quick)
        if not report["scenes"]:
            raise click.BadParameter("none of these scenes knows its exact motion", param_hint="--scene")
        print_report(report)
        write_report(report, plot_path, json_path)
        click.echo(f"wrote {plot_path} and {json_path}")
        return
    accels = _accel_list(accel, "--accel")
    shadow_list = _accel_list(shadow_accels, "--shadow-accel")
    n_threads = set_threads(threads)
    peer_list = []
    if peers:
        from anim.measure.peers import PEER_NAMES, available_peers
        peer_list = available_peers(n_threads)
        if not peer_list:
            raise click.UsageError(f"--peers: none of {', '.join(PEER_NAMES)} imports here; "
                                   "pip install 'frustrace[peers]'")
        click.echo(f"peers: {', '.join(p.name for p in peer_list)}", err=True)
    rows = run_bench(names, res, n_frames, _int_list(packets, "--packet", PACKET_SIZES), n_threads, accels,
                     peer_list, shadow_list)
    bench_table(rows)
    if plot_path:
        from cli.bench import plot_phases
        plot_phases(rows, plot_path)
        click.echo(f"wrote {plot_path}")
    if json_path:
        json_path.write_text(json.dumps(rows, indent=1))


@main.command(context_settings={"ignore_unknown_options": False})
@click.argument("structures", nargs=-1, required=True)
@click.option("--scene", "scene_name", help="A built-in scene instead of ANIM.yaml (see `assets list`).")
@click.option("--frames", "n_frames", type=click.IntRange(1, 10000), default=8, show_default=True,
              help="Frames timed per structure (medians; two warm-up frames come first).")
@click.option("--res", type=click.IntRange(16, 8192),
              help="Image width; the height follows the scene's aspect. Default: the scene file's "
                   "output.resolution (built-in scenes: 1024x1024).")
@click.option("--threads", type=click.IntRange(0, 1024), default=0, show_default=True, help="Threads; 0 = all cores.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write the table as JSON.")
@click.option("--shadow-accel", type=click.Choice(ACCELS),
              help="Structure of every row's shadow rays (default: render.shadow_accel, else bvh).")
@click.option("--camera", metavar="PRIM", help=CAMERA_HELP)
def compare(structures, scene_name, n_frames, res, threads, json_path, shadow_accel, camera):
    """Compare the camera rays' acceleration structures on one scene:
    `compare grid vs kdtree [vs bvh] [ANIM.yaml | --scene NAME]` (ANIM.yaml
    may be a USD stage or an FBX file). Structures: grid, grid-nocull (no frustum culling,
    no mailboxes), kdtree, bvh. Every row's shadow rays go through one
    structure (--shadow-accel). Prints build and trace ms, fps, ray/triangle
    tests and cells/nodes per packet for each, and the largest image difference."""
    import json
    import tempfile

    from anim.measure.bench import scene_file
    from anim.measure.compare import compare as run_compare
    from anim.measure.compare import parse_structures
    from anim.render.paths import writable_file
    from raycore.jit.presets import set_threads

    from cli.report import compare_table
    if json_path:
        writable_file(json_path, "the --json file")
    try:
        names, path = parse_structures(structures)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="STRUCTURES")
    if (path is None) == (scene_name is None):
        raise click.BadParameter("give either ANIM.yaml or --scene NAME", param_hint="STRUCTURES")
    n_threads = set_threads(threads)
    with tempfile.TemporaryDirectory(prefix="frustrace-compare-") as tmp:
        if scene_name is not None:
            from anim import builtin
            if scene_name not in builtin.ALL:
                raise click.BadParameter(f"unknown scene {scene_name!r}", param_hint="--scene")
            path = scene_file(scene_name, Path(tmp))
        result = run_compare(Path(path), names, n_frames, res, n_threads, label=scene_name or str(path),
                             shadow_accel=shadow_accel, camera=camera)
    result["threads"] = n_threads
    timed = result["rows"][0]["frames"]
    if timed < n_frames:
        click.echo(f"frustrace: warning: --frames {n_frames}, but the scene has {timed} frame"
                   f"{'s' if timed != 1 else ''}: {timed} timed", err=True)
    compare_table(result)
    if json_path:
        json_path.write_text(json.dumps(result, indent=1))


@main.group()
def assets():
    """Built-in scenes modelled on the classic animated ray tracing benchmarks
    (hand, runner, toys, marbles, fairy; torus), generated on demand."""


@assets.command("list")
def assets_list():
    """Name, triangle count (and the classic scene's) and motion of each scene."""
    from cli.assets import scene_rows
    for r in scene_rows():
        classic = f"(classic scene: {r['target']:,d})" if r["target"] else ""
        click.echo(f"{r['name']:8s} {r['triangles']:>7,d} triangles {classic:24s} {r['description']}")


@assets.command("make")
@click.argument("name")
@click.option("-o", "--out-dir", type=click.Path(file_okay=False, path_type=Path),
              help="Where to write anim.yaml and its files (default: ./NAME).")
@click.option("--preview", "preview_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Also render the middle frame at 320x320 to this image (.png, .jpg, .tif, .exr, ...).")
@click.option("--overwrite", is_flag=True, help="Replace an existing anim.yaml and the files it names.")
def assets_make(name, out_dir, preview_path, overwrite):
    """Generate built-in scene NAME (meshes, weights, textures, anim.yaml); deterministic."""
    from anim import builtin
    from anim.errors import SceneError
    from anim.render.paths import PREVIEW_FORMATS, writable_dir, writable_file

    from cli.assets import make, render_preview
    if name not in builtin.ALL:
        raise click.BadParameter(f"unknown scene {name!r}; built-in: {', '.join(builtin.ALL)}",
                                 param_hint="NAME")
    out_dir = out_dir or Path(name)
    if (out_dir / "anim.yaml").exists() and not overwrite:
        raise SceneError(out_dir / "anim.yaml", "", "exists (perhaps edited); use --overwrite to replace "
                                                    "the scene and its files")
    writable_dir(out_dir, "the scene")
    if preview_path:
        writable_file(preview_path, "the --preview image", PREVIEW_FORMATS)
    path, seconds = make(name, out_dir)
    click.echo(f"wrote {path} ({seconds:.1f} s)")
    if preview_path:
        render_preview(path, preview_path)
        click.echo(f"wrote {preview_path}")


@main.command()
@click.argument("anim_yaml", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--camera", metavar="PRIM", help=CAMERA_HELP)
@click.option("--strict", is_flag=True,
              help="Also reject file references that leave the scene's directory (absolute paths, "
                   "'..'): a scene shipped to other machines takes its directory only.")
def check(anim_yaml, camera, strict):
    """Validate ANIM_YAML (schema, meshes, keys, camera at every frame,
    textures) and summarise it; render nothing. What passes here, `render`
    accepts. A USD stage or FBX file is described: what came from it, what from
    frustrace's defaults."""
    from anim.render.settings import config_of, one_pass_blur_warning, shading_of
    scene = load_scene(anim_yaml, camera)
    if strict and scene.outside_paths:
        key, ref = scene.outside_paths[0]
        raise SceneError(anim_yaml, key, f"{ref!r} lies outside the scene's directory (--strict)")
    shading_of(scene)                       # reads every texture, as render does
    spec = scene.spec
    moving = sum(1 for o in scene.objects if not o.static)
    click.echo(f"{anim_yaml}: ok")
    click.echo(f"  frames {spec.frames.start}..{spec.frames.end} at {spec.frames.fps:g} fps, "
               f"{spec.output.resolution[0]}x{spec.output.resolution[1]}, spp {spec.render.spp}")
    click.echo(f"  {_count(len(scene.objects), 'object')} ({moving} moving), "
               f"{_count(scene.faces.shape[0], 'triangle')}, {_count(scene.n_vertices, 'vertex', 'vertices')}"
               + (f"; {scene.flat_triangles:,} triangles with every copy, {len(scene.instance_proto):,} copies traced "
                  f"two-level" if scene.two_level else ""))
    click.echo(f"  {_count(len(spec.lights), 'light')}, {_count(len(scene.materials) - 1, 'material')}, "
               f"{_count(len(scene.texture_paths), 'texture')}, "
               f"camera {'animated' if spec.camera.keys else 'static'}")
    blur, cam = spec.render.motion_blur, spec.camera
    if (blur_warning := one_pass_blur_warning(config_of(scene))) is not None:
        click.echo(f"  warning: {blur_warning}")
    if blur.shutter > 0:
        click.echo(f"  motion blur: shutter {blur.shutter:g} frame intervals ({blur.shutter / spec.frames.fps * 1e3:.4g} ms), "
                   f"{blur.position}; one shutter time per pass, {spec.render.spp} per frame"
                   + ("" if moving or cam.keys else " (nothing moves: off)"))
    if cam.aperture_radius > 0:
        focus = f"{cam.focus_distance:g}" if cam.focus_distance else "the eye's distance to look_at"
        click.echo(f"  depth of field: aperture radius {cam.aperture_radius:g}, focus distance {focus}; "
                   f"one lens position per pass, {spec.render.spp} per frame")
    for o in scene.objects:
        kind = "static" if o.static else ("rigid" if o.rigid else "deforming")
        if o.instances is not None:
            kind = (f"{o.instances.n:,} copies of {_count(len(o.proto_faces), 'triangle')}, "
                    f"{'still' if o.static else 'moving'}")
        meshes = o.usd.meshes if o.usd is not None else ()
        copies = sum(getattr(m, "n_instances", 0) for m in meshes)
        if copies:
            kind += f", {copies:,} point-instanced copies"
        proxies = sum(len(m.proxies) for m in meshes if hasattr(m, "proxies"))
        if proxies:
            kind += f", {proxies:,} instanceable copies sharing their prototypes' meshes"
        if o.two_level:
            kind += ", traced two-level"
        click.echo(f"    {o.name}: {_count(len(o.faces), 'triangle')}, {kind}")
    for note in scene.notes:
        click.echo(f"  {note}")


def _count(n, one, many=None):
    """'1 light', '2 lights'."""
    return f"{n} {one if n == 1 else (many or one + 's')}"


def entry():
    """The `frustrace` command: main(), and an exit without the
    interpreter's teardown, whose garbage collection over numba's and the
    libraries' objects took 0.3-0.4 s of every run (a fifth of the demo's
    warm start). Registered first, leave() runs last: after Python has
    joined the threads and run every atexit function registered later
    (libraries' own), it flushes the standard streams and ends the process
    with main's exit status (os._exit; the trick of Instagram's
    "Dismissing Python garbage collection")."""
    status = [1]                 # an exception main did not turn into an exit: 1

    def leave():
        if "logging" in sys.modules:
            sys.modules["logging"].shutdown()
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:    # a closed pipe: nothing more can be said
                pass
        os._exit(status[0])

    atexit.register(leave)
    try:
        main()
        status[0] = 0
    except SystemExit as exc:
        code = exc.code
        status[0] = 0 if code is None else code if isinstance(code, int) else 1
        raise
    except KeyboardInterrupt:
        status[0] = 130
        raise


if __name__ == "__main__":
    entry()
