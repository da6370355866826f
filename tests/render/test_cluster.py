"""Frames on Dask (anim/render/cluster.py), with real processes: an embedded
LocalCluster, a `dask scheduler` with `dask worker`s started here (one of
them killed mid-render), TLS with certificates made here, an unreachable
scheduler, --resume, and Ctrl-C leaving no process behind."""
import datetime
import json
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np
import pytest

from raycore.images.image_io import read_exr

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "anim" / "builtin" / "demo" / "anim.yaml"
BIN = Path(sys.executable).parent
ARGS = ["--res", "96x72", "-q"]


def frustrace(*args, env=None, **kw):
    return subprocess.Popen([sys.executable, "-m", "cli.main", *map(str, args)], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def run(*args, timeout=300, env=None):
    proc = frustrace(*args, env=env)
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out + err


# the connect timeout shortened from 10 s (the tests wait for it to pass)
SHORT_CONNECT = {**os.environ, "FRUSTRACE_CONNECT_TIMEOUT_S": "3"}


def frames_in(d: Path):
    return sorted(p.name for p in d.glob("frame_*.exr"))


def same_frames(a: Path, b: Path, names):
    for name in names:
        ca, pa, _ = read_exr(str(a / name))
        cb, pb, _ = read_exr(str(b / name))
        assert ca == cb, name
        np.testing.assert_array_equal(pa, pb, err_msg=name)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The first 16 frames rendered in one process."""
    out = tmp_path_factory.mktemp("single")
    code, text = run("render", DEMO, "-o", out, "--frames", "0:15", *ARGS)
    assert code == 0, text
    return out


def test_local_workers_give_the_single_process_frames(tmp_path, reference):
    out = tmp_path / "local"
    code, text = run("render", DEMO, "-o", out, "--frames", "0:15", "--workers", "2", "--chunk", "3", *ARGS)
    assert code == 0, text
    assert frames_in(out) == frames_in(reference)
    same_frames(out, reference, frames_in(reference))
    stats = json.loads((out / "stats.json").read_text())
    assert sorted(r["frame"] for r in stats["frames"]) == list(range(16))
    workers = stats["runs"][-1]["workers"]
    assert len(workers) == 2 and sum(w["frames"] for w in workers.values()) == 16
    assert all(w["compile_s"] >= 0 and w["fps"] > 0 for w in workers.values())
    assert {r["worker"] for r in stats["frames"]} == set(workers)
    assert all(r["bytes"] > 1000 for r in stats["frames"])


def test_resume_on_a_cluster_skips_finished_frames(tmp_path, reference):
    out = tmp_path / "resume"
    code, text = run("render", DEMO, "-o", out, "--frames", "0:5", *ARGS)
    assert code == 0, text
    before = {p.name: p.stat().st_mtime_ns for p in out.glob("frame_*.exr")}
    code, text = run("render", DEMO, "-o", out, "--frames", "0:15", "--resume", "--workers", "2", *ARGS)
    assert code == 0, text
    assert {p.name: p.stat().st_mtime_ns for p in out.glob("frame_*.exr") if p.name in before} == before
    same_frames(out, reference, frames_in(reference))
    stats = json.loads((out / "stats.json").read_text())
    assert stats["runs"][-1]["frames_rendered"] == 10
    assert sorted(r["frame"] for r in stats["frames"]) == list(range(16))


def test_an_unreachable_scheduler_is_one_line_and_exit_2(tmp_path):
    t0 = time.monotonic()
    code, text = run("render", DEMO, "-o", tmp_path / "x", "--scheduler", "tcp://127.0.0.1:9", *ARGS, timeout=120,
                     env=SHORT_CONNECT)
    assert code == 2, text
    lines = text.strip().splitlines()
    assert len(lines) == 1 and "tcp://127.0.0.1:9" in lines[0] and "Traceback" not in text
    assert time.monotonic() - t0 < 60
    assert not (tmp_path / "x").exists() or frames_in(tmp_path / "x") == []


class Cluster:
    """A `dask scheduler` and `dask worker`s on 127.0.0.1, as a user starts them."""

    def __init__(self, tmp_path, n_workers, tls=None):
        self.file = tmp_path / "scheduler.json"
        self.tls = tls or []
        self.procs = []
        protocol = ["--protocol", "tls"] if tls else []
        self.scheduler = self._start([BIN / "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
                                      "--no-dashboard", "--scheduler-file", self.file, *protocol,
                                      *self._tls_args()])
        deadline = time.monotonic() + 60
        while not self.file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        self.address = json.loads(self.file.read_text())["address"]
        self.workers = [self._start([BIN / "dask", "worker", self.address, "--nthreads", "1",
                                     "--host", "127.0.0.1", "--no-dashboard", "--name", f"w{i}",
                                     *self._tls_args()]) for i in range(n_workers)]

    def _tls_args(self):
        if not self.tls:
            return []
        ca, cert, key = self.tls
        return ["--tls-ca-file", ca, "--tls-cert", cert, "--tls-key", key]

    def _start(self, cmd):
        proc = subprocess.Popen([str(c) for c in cmd], cwd=ROOT, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        self.procs.append(proc)
        return proc

    def close(self):
        for p in self.procs:
            if p.poll() is None:
                p.kill()
            p.wait(timeout=30)


def test_a_worker_killed_mid_render_loses_and_repeats_no_frame(tmp_path, reference):
    cluster = Cluster(tmp_path, 2)
    try:
        out = tmp_path / "remote"
        proc = frustrace("render", DEMO, "-o", out, "--frames", "0:15", "--scheduler", cluster.address,
                         "--chunk", "2", *ARGS)
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and proc.poll() is None and len(frames_in(out) if out.exists() else []) < 2:
            time.sleep(0.05)
        cluster.workers[0].send_signal(signal.SIGKILL)
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err
        assert frames_in(out) == frames_in(reference)
        same_frames(out, reference, frames_in(reference))
        stats = json.loads((out / "stats.json").read_text())
        assert sorted(r["frame"] for r in stats["frames"]) == list(range(16))     # each frame once
        assert not [p for p in out.iterdir() if p.name.startswith(".")]
    finally:
        cluster.close()


def make_certificates(d: Path):
    """A CA and one certificate for 127.0.0.1 signed by it (PEM files)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID
    import ipaddress
    now = datetime.datetime.now(datetime.timezone.utc)

    def name(cn):
        return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)])
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca = (x509.CertificateBuilder().subject_name(name("frustrace test CA")).issuer_name(name("frustrace test CA"))
          .public_key(ca_key.public_key()).serial_number(x509.random_serial_number())
          .not_valid_before(now - datetime.timedelta(minutes=5)).not_valid_after(now + datetime.timedelta(days=1))
          .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
          .sign(ca_key, hashes.SHA256()))
    key = ec.generate_private_key(ec.SECP256R1())
    cert = (x509.CertificateBuilder().subject_name(name("127.0.0.1")).issuer_name(ca.subject)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5)).not_valid_after(now + datetime.timedelta(days=1))
            .add_extension(x509.SubjectAlternativeName([x509.IPAddress(ipaddress.ip_address("127.0.0.1")),
                                                        x509.DNSName("localhost")]), critical=False)
            .sign(ca_key, hashes.SHA256()))
    paths = d / "ca.pem", d / "cert.pem", d / "key.pem"
    paths[0].write_bytes(ca.public_bytes(serialization.Encoding.PEM))
    paths[1].write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    paths[2].write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    return paths


def test_a_render_over_tls_with_certificates(tmp_path, reference):
    ca, cert, key = make_certificates(tmp_path)
    cluster = Cluster(tmp_path, 1, tls=(ca, cert, key))
    try:
        assert cluster.address.startswith("tls://")
        out = tmp_path / "tls"
        code, text = run("render", DEMO, "-o", out, "--frames", "0:3", "--scheduler", cluster.address,
                         "--tls-ca", ca, "--tls-cert", cert, "--tls-key", key, *ARGS)
        assert code == 0, text
        same_frames(out, reference, [f"frame_{i:04d}.exr" for i in range(4)])
        # without the certificates the scheduler is not reached
        code, text = run("render", DEMO, "-o", tmp_path / "plain", "--frames", "0:3", "--scheduler",
                         cluster.address, *ARGS, timeout=120)
        assert code == 2 and len(text.strip().splitlines()) == 1, text
    finally:
        cluster.close()


def _processes_with(marker: str):
    found = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if marker.encode() in (d / "environ").read_bytes():
                    found.append(int(d.name))
            except OSError:
                pass
    return found


def test_ctrl_c_cancels_and_leaves_no_worker_process(tmp_path):
    marker = f"FRUSTRACE_TEST_MARK={uuid.uuid4().hex}"
    env = {**os.environ, marker.split("=")[0]: marker.split("=")[1]}
    out = tmp_path / "cancel"
    proc = frustrace("render", DEMO, "-o", out, "--frames", "0:119", "--workers", "2", "--chunk", "1",
                     *ARGS, env=env)
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None and len(frames_in(out) if out.exists() else []) < 2:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    deadline = time.monotonic() + 30
    while _processes_with(marker) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert _processes_with(marker) == []
    stats = json.loads((out / "stats.json").read_text())
    assert 2 <= len(stats["frames"]) < 120
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def test_a_task_that_raises_names_its_frame_and_keeps_the_frames_before(tmp_path):
    """A worker's error (here: frames past the first chunk given a packet
    size the grid does not have) ends the render with the frame and the
    error named; the chunks finished before it are on disk."""
    from distributed import Client

    from anim.render import cluster
    from anim.render.job import FrameRenderError, RenderJob, render_animation
    from anim.render.settings import config_of
    from anim.scene import AnimatedScene

    scene = AnimatedScene(DEMO)
    cfg = config_of(scene, width=48, height=36, threads=1)
    real = cluster.render_chunk

    def failing_chunk(bundle, cfg_fields, frames, *args):
        if frames[0] >= 4:
            cfg_fields = {**cfg_fields, "packet": 3}
        return real(bundle, cfg_fields, frames, *args)
    cluster.render_chunk = failing_chunk
    try:
        with Client(processes=False, n_workers=1, threads_per_worker=1, dashboard_address=None) as client:
            job = RenderJob(scene, cfg, list(range(8)), tmp_path, tmp_path / "stats.json", False, False, chunk=4)
            with pytest.raises(FrameRenderError, match=r"frame 4 on .*packet must be one of"):
                render_animation(job, client=client)
    finally:
        cluster.render_chunk = real
    assert frames_in(tmp_path) == [f"frame_{i:04d}.exr" for i in range(4)]
    stats = json.loads((tmp_path / "stats.json").read_text())
    assert [r["frame"] for r in stats["frames"]] == [0, 1, 2, 3]
    assert stats["runs"][-1]["ended"].startswith("failed: frame 4")


@pytest.mark.parametrize("content, words", [
    (None, ["not found"]), ("nope", ["is not JSON"]), ('{"x": 1}', ['has no "address"']),
])
def test_a_bad_scheduler_file_is_named_in_one_line(tmp_path, content, words):
    """Issue 20: AssertionError (empty) for a file that is not JSON or has
    no address, "missing port number" for a missing file."""
    path = tmp_path / "scheduler.json"
    if content is not None:
        path.write_text(content)
    code, text = run("render", DEMO, "-o", tmp_path / "x", "--scheduler", path, *ARGS, timeout=120)
    lines = text.strip().splitlines()
    assert code == 2 and len(lines) == 1 and str(path) in lines[0] and all(w in lines[0] for w in words), text


@pytest.mark.parametrize("reply", [b"", b"\xff" * 64 + b"HTTP/1.0 200 OK\r\n\r\n"], ids=["silent", "garbage"])
def test_a_port_that_is_not_a_scheduler_is_one_line_within_the_timeout(tmp_path, reply):
    """Issue 20: a port that answers but is not a Dask scheduler (a
    dashboard's) hung until Ctrl-C; one that answered oddly gave an
    internal error allocating exabytes."""
    import socket
    import threading
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    held = []

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            held.append(conn)                     # kept open, answering nothing more
            if reply:
                conn.sendall(reply)
    threading.Thread(target=serve, daemon=True).start()
    address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
    t0 = time.monotonic()
    try:
        code, text = run("render", DEMO, "-o", tmp_path / "x", "--scheduler", address, *ARGS, timeout=120,
                         env=SHORT_CONNECT)
    finally:
        server.close()
        for c in held:
            c.close()
    lines = text.strip().splitlines()
    assert code == 2 and len(lines) == 1 and address in lines[0] and "internal error" not in text, text
    assert time.monotonic() - t0 < 30
    assert not (tmp_path / "x").exists()


def test_a_scheduler_without_workers_is_one_line_after_the_wait(tmp_path):
    """Issue 20: `internal error: TimeoutError: No valid workers found`, exit 1."""
    sched = subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                              "--scheduler-file", str(tmp_path / "s.json")], stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while not (tmp_path / "s.json").exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        env = {**os.environ, "FRUSTRACE_WORKER_WAIT_S": "1"}
        proc = frustrace("render", DEMO, "-o", tmp_path / "x", "--scheduler", tmp_path / "s.json", *ARGS, env=env)
        out, err = proc.communicate(timeout=120)
    finally:
        sched.kill()
        sched.wait(timeout=30)
    lines = (out + err).strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "has no workers" in lines[0] and "waited 1 s" in lines[0], err


def test_ctrl_c_to_the_whole_process_group_prints_one_line(tmp_path):
    """Issue 20: a terminal's Ctrl-C reaches the workers too, and one of
    them printed a 29-line traceback before the render's line: the embedded
    cluster's workers now ignore SIGINT and are stopped by the render."""
    out = tmp_path / "cancel"
    proc = frustrace("render", DEMO, "-o", out, "--frames", "0:119", "--workers", "2", "--chunk", "1", *ARGS,
                     start_new_session=True)
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None and len(frames_in(out) if out.exists() else []) < 2:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("frustrace: interrupted"), err


def test_cluster_options_without_a_cluster_are_warned(tmp_path):
    code, text = run("render", DEMO, "-o", tmp_path / "x", "--frames", "0:0", "--chunk", "3", *ARGS)
    assert code == 0 and "--chunk is for --workers or --scheduler" in text
