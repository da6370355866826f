"""Frames on a Dask cluster: an embedded LocalCluster (`render --workers N`)
or an existing one (`render --scheduler ADDRESS`).

The scene travels, not the file system: the client packs the scene file and
every file it references into one bundle (bytes by relative path), sends it
to every worker once, and each worker unpacks it into a directory of its
own, builds the scene, compiles (or loads) the kernels and keeps all of it
for the tasks that follow. A task is a chunk of consecutive frames (the
grid of the static objects is kept from frame to frame); the worker returns
each frame as encoded EXR bytes, so compression runs on the workers, and the
client writes them atomically, as the single-process path does. Dask
retries a chunk whose worker died elsewhere; its frames reach the client
only when the whole chunk is done, so none is written twice.
"""
import hashlib
import json
import os
import socket
import tempfile
import threading
import time
from pathlib import Path
from typing import NamedTuple

from anim.errors import SceneError
from anim.io.usd import is_usd

# the worker's scenes: bundle digest -> WorkerScene (kept between tasks)
_WORKER_SCENES = {}
# how long connecting to a scheduler may take (FRUSTRACE_CONNECT_TIMEOUT_S)
CONNECT_TIMEOUT_S = float(os.environ.get("FRUSTRACE_CONNECT_TIMEOUT_S", "10"))
# how long a scheduler without workers is given to get one (FRUSTRACE_WORKER_WAIT_S)
WORKER_WAIT_S = float(os.environ.get("FRUSTRACE_WORKER_WAIT_S", "30"))
TASK_RETRIES = 3


class Bundle(NamedTuple):
    """A scene and its files: name of the scene file, {relative path: bytes}."""
    scene_name: str
    files: dict
    digest: str
    camera: str = None        # a USD stage's or FBX file's chosen camera (render --camera)
    instancing: str = None    # render --instancing


def referenced_files(scene) -> list:
    """(key, relative path) of every file the scene reads, the scene file
    first; glTF meshes bring their external buffers and images. A reference
    outside the scene's directory cannot travel: SceneError naming its key."""
    if scene.outside_paths:
        key, ref = scene.outside_paths[0]
        raise SceneError(scene.path, key, f"{ref!r} lies outside the scene's directory, so it cannot be "
                                          "sent to the workers (keep every file under the scene's directory)")
    spec, base = scene.spec, scene.path.parent
    refs = [("", scene.path.name)]
    refs += [(f"materials.{n}.texture", m.texture) for n, m in spec.materials.items() if m.texture]
    usd_done = set()
    for i, o in enumerate(spec.objects):
        if o.mesh:
            refs.append((f"objects.{i}.mesh", o.mesh))
            if o.mesh.lower().endswith(".gltf"):
                refs += [(f"objects.{i}.mesh", uri) for uri in _gltf_uris(base / o.mesh, o.mesh)]
            if o.mesh.lower().endswith(".fbx"):                   # its textures, found beside it
                refs += [(f"objects.{i}.mesh", os.path.relpath(f, base))
                         for f in scene.objects[i].fbx.texture_files]
            if is_usd(o.mesh) and o.mesh not in usd_done:       # a stage's objects share its files
                usd_done.add(o.mesh)
                refs += [(f"objects.{i}.mesh", ref) for ref in _usd_files(base, o.mesh, scene.path, i)]
        for j, k in enumerate(o.keyframes or []):
            refs.append((f"objects.{i}.keyframes.{j}.mesh", k.mesh))
        if o.skeleton:
            refs.append((f"objects.{i}.skeleton.weights", o.skeleton.weights))
        if o.instances is not None and o.instances.file:
            refs.append((f"objects.{i}.instances.file", o.instances.file))
    seen, out = set(), []
    for key, ref in refs:
        if ref not in seen:
            seen.add(ref)
            out.append((key, ref))
    return out


def _gltf_uris(path: Path, ref: str) -> list:
    """The external files (buffers, images) of a .gltf, relative to the scene."""
    import json
    from urllib.parse import unquote
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return []
    uris = [item.get("uri") for kind in ("buffers", "images") for item in doc.get(kind, [])]
    folder = os.path.dirname(ref)
    return [os.path.join(folder, unquote(u)) for u in uris if u and not u.startswith("data:")]


def _usd_files(base: Path, ref: str, scene_path, index) -> list:
    """The layers and assets (textures) a USD stage reads, relative to the scene."""
    from anim.io.usd import dependencies
    out = []
    root = base.resolve()
    for dep in dependencies(base / ref):
        dep = dep.resolve()
        if not dep.is_relative_to(root):
            raise SceneError(scene_path, f"objects.{index}.mesh", f"{ref} reads {dep}, which lies outside the "
                                                                   "scene's directory, so it cannot be sent to the workers")
        out.append(str(dep.relative_to(root)))
    return out


def bundle_scene(scene) -> Bundle:
    """The scene file and every file it references, read once on the client."""
    files = {}
    for key, ref in referenced_files(scene):
        try:
            files[ref] = (scene.path.parent / ref).read_bytes()
        except OSError as exc:
            raise SceneError(scene.path, key, f"cannot read {ref}: {exc.strerror or exc}") from None
    h = hashlib.sha256()
    for ref in sorted(files):
        h.update(ref.encode())
        h.update(hashlib.sha256(files[ref]).digest())
    h.update(str(scene.camera_choice).encode())
    h.update(str(scene.instancing_choice).encode())
    return Bundle(scene.path.name, files, h.hexdigest()[:16], scene.camera_choice, scene.instancing_choice)


class WorkerScene(NamedTuple):
    scene: object
    renderer: object
    compile_s: float
    directory: object         # the TemporaryDirectory holding the unpacked files


def _worker_scene(bundle: Bundle, cfg_fields: dict) -> WorkerScene:
    """This worker's copy of the scene, unpacked, loaded and warmed up once."""
    from anim.scene import AnimatedScene
    from raycore.config import RenderConfig

    from anim.render.renderer import SceneRenderer

    from anim.render.warm_up import warm_up
    from anim.render.settings import shading_of
    from anim.render.warm_lock import warm_once
    key = (bundle.digest, tuple(sorted(cfg_fields.items())))
    if key in _WORKER_SCENES:
        return _WORKER_SCENES[key]
    directory = tempfile.TemporaryDirectory(prefix="frustrace-scene-")
    root = Path(directory.name)
    for ref, data in bundle.files.items():
        target = root / ref
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
    scene = AnimatedScene(root / bundle.scene_name, bundle.camera, bundle.instancing)
    cfg = RenderConfig(**cfg_fields)
    shading = shading_of(scene)
    # one cold compile per machine, not one per worker (warm_lock.py)
    renderer = SceneRenderer(scene, cfg, shading)
    compile_s, _ = warm_once(repr(key), lambda: warm_up(scene, shading, cfg, scene.time_of(scene.frame_numbers[0]),
                                                        structures=renderer.structures))
    _WORKER_SCENES[key] = WorkerScene(scene, renderer, compile_s, directory)
    return _WORKER_SCENES[key]


def render_chunk(bundle: Bundle, cfg_fields: dict, frames: list, compression: str, version: str,
                 run_info: dict) -> list:
    """Run on a worker: [(frame, exr bytes, stats row)] of consecutive frames.
    An error names its frame."""
    from raycore.jit.presets import set_threads
    from raycore.images.image_io import write_exr

    from anim.render.stats import frame_metadata, frame_row
    set_threads(cfg_fields["threads"])
    worker = _worker_name()
    try:
        ws = _worker_scene(bundle, cfg_fields)
    except Exception as exc:
        raise RuntimeError(f"frame {frames[0]} on {worker}, preparing the scene: "
                           f"{type(exc).__name__}: {exc}") from exc
    out = []
    for frame in frames:
        try:
            t = ws.scene.time_of(frame)
            interp_ms, result = ws.renderer.render(t)
            row = {**frame_row(ws.scene, frame, t, interp_ms, result), "worker": worker,
                   "worker_compile_s": ws.compile_s}
            t0 = time.perf_counter()
            path = os.path.join(ws.directory.name, f"frame.{os.getpid()}.exr")
            write_exr(path, {"RGBA": result.rgba, "Z": result.z, **result.aovs},
                      frame_metadata(row, version, run_info), compression)
            with open(path, "rb") as f:
                data = f.read()
            os.remove(path)
            row["encode_ms"] = (time.perf_counter() - t0) * 1e3
        except Exception as exc:
            raise RuntimeError(f"frame {frame} on {worker}: {type(exc).__name__}: {exc}") from exc
        out.append((frame, data, row))
    return out


def _worker_name() -> str:
    """The Dask worker's name (its address unless it was given one)."""
    try:
        from distributed import get_worker
        worker = get_worker()
    except (ImportError, ValueError):          # not inside a Dask task
        return f"{socket.gethostname()}:{os.getpid()}"
    return worker.name if isinstance(worker.name, str) else worker.address


def chunks_of(frames: list, chunk: int) -> list:
    """Runs of at most `chunk` frames, in order."""
    return [frames[i:i + chunk] for i in range(0, len(frames), chunk)]


def security_of(tls_ca=None, tls_cert=None, tls_key=None):
    """Dask Security for tls:// addresses from certificate files (None: Dask's
    own configuration)."""
    if not (tls_ca or tls_cert or tls_key):
        return None
    from distributed.security import Security
    for what, path in (("--tls-ca", tls_ca), ("--tls-cert", tls_cert), ("--tls-key", tls_key)):
        if not path or not Path(path).is_file():
            raise SceneError(what, "", f"needs a readable file (got {path!r}); give all three of "
                                       "--tls-ca, --tls-cert and --tls-key")
    return Security(tls_ca_file=str(tls_ca), tls_client_cert=str(tls_cert), tls_client_key=str(tls_key),
                    require_encryption=True)


def scheduler_address(scheduler: str) -> str:
    """The address behind --scheduler: itself, or the `address` of a
    scheduler file (a name ending in .json, or one that exists); a file
    that is missing, not JSON or without an address is named (SceneError)."""
    looks_like_file = scheduler.endswith(".json") or ("://" not in scheduler and Path(scheduler).exists())
    if not looks_like_file:
        return scheduler
    path = Path(scheduler)
    try:
        info = json.loads(path.read_text())
    except FileNotFoundError:
        raise SceneError("--scheduler", "", f"scheduler file {scheduler} not found") from None
    except OSError as exc:
        raise SceneError("--scheduler", "", f"cannot read scheduler file {scheduler}: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise SceneError("--scheduler", "", f"scheduler file {scheduler} is not JSON ({exc})") from None
    address = info.get("address") if isinstance(info, dict) else None
    if not isinstance(address, str) or not address:
        raise SceneError("--scheduler", "", f"scheduler file {scheduler} has no \"address\" (is it the file "
                                            "`dask scheduler --scheduler-file` wrote?)")
    return address


# what the embedded cluster's fork server imports once for all its workers
WORKER_PRELOAD = ["numba", "anim.render.cluster", "anim.render.job", "anim.render.renderer",
                  "raycore.images.image_io"]


def _fork_workers_from_a_server():
    """Start the embedded cluster's workers from multiprocessing's fork
    server, which imports Dask and frustrace once, instead of Dask's default
    (spawn: a fresh interpreter per worker that imports everything itself).
    Measured (2 vCPU, warm cache): `--workers 2` of 16 small demo frames
    2.3-2.6 s and 3.8-4.2 s of CPU spawned, 1.9-2.0 s and 2.6-2.8 s forked;
    tests/render/test_cluster.py 28 + 6.4 s of CPU, then 17 + 3.0 s. Nothing imported starts a thread,
    so the fork is safe. A method set in Dask's configuration other than its
    default is kept, and so is spawn where there is no fork server (Windows).
    The server is started inside connect()'s SIGINT-ignoring window, so its
    workers ignore Ctrl-C as spawned ones do."""
    import multiprocessing
    from multiprocessing import forkserver

    import dask
    from distributed.utils import get_mp_context
    key = "distributed.worker.multiprocessing-method"
    if dask.config.get(key) != "spawn" or "forkserver" not in multiprocessing.get_all_start_methods():
        return
    dask.config.set({key: "forkserver"})
    context = get_mp_context()              # sets Dask's own preload: distributed and its packages
    theirs = list(getattr(forkserver._forkserver, "_preload_modules", None) or ["distributed"])
    context.set_forkserver_preload(theirs + [m for m in WORKER_PRELOAD if m not in theirs])


def connect(scheduler=None, workers=None, security=None):
    """(client, cluster or None): an embedded LocalCluster of `workers`
    processes listening on 127.0.0.1 only, or a connection to `scheduler`
    (an address or a scheduler file). Whatever the other end does, the
    answer comes within CONNECT_TIMEOUT_S: a port that answers
    but is not a Dask scheduler (a dashboard's HTTP) made Dask's handshake
    wait forever, and one that answered with other bytes made it allocate
    exabytes; both are one line and exit 2 (SceneError, naming the address)."""
    import logging
    import signal

    from distributed import Client, LocalCluster
    logging.getLogger("distributed").setLevel(logging.ERROR)
    if scheduler is None:
        # the workers ignore Ctrl-C: the terminal sends it to the whole process
        # group, and a worker that took it printed its own traceback before
        # the render's one line; this process stops them when it ends
        main_thread = threading.current_thread() is threading.main_thread()
        before = signal.signal(signal.SIGINT, signal.SIG_IGN) if main_thread else None
        try:
            _fork_workers_from_a_server()
            # the workers' own logs stay quiet: a task's failure reaches this
            # process through its future (one line, exit 1), and what a worker
            # logs while the render stops it (a heartbeat to the scheduler
            # that has just closed, on a loaded host) is teardown noise
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   host="127.0.0.1", dashboard_address=None, silence_logs=logging.CRITICAL)
        finally:
            if main_thread:
                signal.signal(signal.SIGINT, before)
        return Client(cluster), cluster
    address = scheduler_address(scheduler)
    kwargs = {"timeout": CONNECT_TIMEOUT_S - 2}          # Dask's own error first, if it has one
    if security is not None:
        kwargs["security"] = security
    result = {}

    def attempt():
        try:
            result["client"] = Client(address, **kwargs)
        except BaseException as exc:          # handed to the caller below
            result["error"] = exc
    thread = threading.Thread(target=attempt, daemon=True, name="frustrace-connect")
    thread.start()
    thread.join(CONNECT_TIMEOUT_S)
    if thread.is_alive():
        raise SceneError("--scheduler", "", f"no Dask scheduler answered at {address} within "
                                            f"{CONNECT_TIMEOUT_S:g} s (something listens there: a dashboard's "
                                            "port? the scheduler's is 8786 by default)") from None
    exc = result.get("error")
    if exc is None:
        client = result["client"]
        try:
            client.wait_for_workers(1, timeout=WORKER_WAIT_S)
        except TimeoutError:
            client.close()
            raise SceneError("--scheduler", "", f"the scheduler at {address} has no workers (waited "
                                                f"{WORKER_WAIT_S:g} s; start one with `dask worker {address}`)") from None
        return client, None
    if isinstance(exc, TypeError) and "ssl" in str(exc).lower():   # tls:// without certificates
        raise SceneError("--scheduler", "", f"{address} needs TLS certificates: give --tls-ca, "
                                            "--tls-cert and --tls-key (or set them in Dask's configuration)") from None
    if isinstance(exc, MemoryError):
        raise SceneError("--scheduler", "", f"{address} answered, but not as a Dask scheduler does") from None
    if isinstance(exc, (OSError, TimeoutError, ValueError, AssertionError)):
        raise SceneError("--scheduler", "", f"cannot reach the Dask scheduler at {address}: "
                                            f"{type(exc).__name__}: {exc}".splitlines()[0]) from None
    raise exc
