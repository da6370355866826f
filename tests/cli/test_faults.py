"""Faults during a render: SIGKILL and resume, Ctrl-C and SIGTERM, a full
disk or a vanished directory, two renders sharing one directory, and a long
run's memory. Nothing finished is lost, nothing broken is left."""
import errno
import json
import os
import random
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cli.main import main
from fork_launcher import Forked
from raycore.images.image_io import read_exr

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "anim" / "builtin" / "demo" / "anim.yaml"
N_FRAMES = 40
ARGS = ["--frames", f"0:{N_FRAMES - 1}", "--res", "96x72", "-q"]
KILLS = int(os.environ.get("FRUSTRACE_KILLS", "20"))


def frustrace(*args, **kw):
    """Start frustrace in a new process (the way a user or a farm runs it),
    with Ctrl-C at its default: a test suite started in the background of a
    shell inherits SIGINT ignored, and Python then leaves it ignored."""
    return subprocess.Popen([sys.executable, "-m", "cli.main", *map(str, args)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL), **kw)


def forked(log_dir: Path, *args):
    """frustrace in a process forked from a server that has imported it
    (fork_launcher.py: ~0.1 s to start instead of ~0.8), for the renders
    started only to be killed or raced; what a fresh process does on a
    signal is tested with frustrace()."""
    return Forked(args, ROOT, log_dir)


def exr_frames(d: Path):
    return sorted(p for p in d.glob("frame_*.exr"))


def leftovers(d: Path):
    """Temporary frames, claims and stats temporaries: none may survive a run that ended."""
    return [p.name for p in d.iterdir() if p.name.startswith(".")]


def pixels(path):
    names, px, _ = read_exr(str(path))
    return names, px


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("reference")
    proc = forked(tmp_path_factory.mktemp("logs"), "render", DEMO, "-o", out, *ARGS)
    assert proc.wait(timeout=300) == 0, proc.stderr.read()
    return out


def test_sigkill_at_random_moments_then_resume_loses_and_repeats_nothing(tmp_path, reference):
    """KILLS times: start a --resume render, SIGKILL it once a random number of
    frames is on disk (plus a random few ms, so kills land mid-write too);
    finished frames are never rendered again; at the end every frame equals
    the uninterrupted render and nothing temporary is left."""
    rng = random.Random(7)
    out = tmp_path / "out"
    kills = 0
    while kills < KILLS:
        before = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in exr_frames(out)} if out.exists() else {}
        if len(before) == N_FRAMES:
            break
        proc = forked(tmp_path / "logs", "render", DEMO, "-o", out, "--resume", *ARGS)
        target = min(N_FRAMES - 1, len(before) + rng.randint(1, 4))
        while proc.poll() is None and (len(exr_frames(out)) if out.exists() else 0) < target:
            time.sleep(0.002)
        time.sleep(rng.uniform(0, 0.01))
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
            kills += 1
        proc.wait(timeout=60)
        for p in exr_frames(out):            # finished frames stay as they were
            if p.name in before:
                assert (p.stat().st_ino, p.stat().st_mtime_ns) == before[p.name], f"{p.name} rendered again"
    assert kills >= min(KILLS, 10)
    proc = forked(tmp_path / "logs", "render", DEMO, "-o", out, "--resume", *ARGS)
    assert proc.wait(timeout=300) == 0, proc.stderr.read()
    assert [p.name for p in exr_frames(out)] == [p.name for p in exr_frames(reference)]
    for p in exr_frames(out):
        names, got = pixels(p)
        ref_names, want = pixels(reference / p.name)
        assert names == ref_names == ["R", "G", "B", "A", "Z"]
        np.testing.assert_array_equal(got, want)
    assert leftovers(out) == []
    stats = json.loads((out / "stats.json").read_text())
    assert [f["frame"] for f in stats["frames"]] == list(range(N_FRAMES))
    # issue 20: a killed run's frames come back with their run (listed as
    # killed, its settings from their headers), their write time unknown
    # (not 0), and the summary's median write over the frames that measured it
    runs = stats["runs"]
    for f in stats["frames"]:
        assert isinstance(f.get("run"), int) and 0 <= f["run"] < len(runs)
        if f.get("recovered"):
            assert f["write_ms"] is None and runs[f["run"]]["ended"] == "killed"
            assert runs[f["run"]]["accel"] == "grid" and runs[f["run"]]["frames_rendered"] >= 1
        else:
            assert f["write_ms"] > 0 and isinstance(f["crc32"], int)
    assert any(f.get("recovered") for f in stats["frames"])
    # the median write over the frames that measured it; unknown (null) when
    # the last run found every frame written by killed runs
    measured = [f for f in stats["frames"] if f["write_ms"] is not None]
    median_write = stats["summary"]["median_ms"]["write_ms"]
    assert (median_write > 0) if measured else (median_write is None), (median_write, len(measured))


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_ctrl_c_and_sigterm_keep_stats_and_leave_no_broken_file(tmp_path, sig, code):
    out = tmp_path / "out"
    proc = frustrace("render", DEMO, "-o", out, *ARGS)
    while proc.poll() is None and (len(exr_frames(out)) if out.exists() else 0) < 3:
        time.sleep(0.002)
    proc.send_signal(sig)
    assert proc.wait(timeout=60) == code
    err = proc.stderr.read()
    assert "stats.json" in err and "half-written" in err
    done = exr_frames(out)
    stats = json.loads((out / "stats.json").read_text())
    assert [f["frame"] for f in stats["frames"]] == [int(p.stem[-4:]) for p in done]
    assert stats["runs"][-1]["ended"] == "interrupted" and 3 <= len(done) < N_FRAMES
    for p in done:
        assert pixels(p)[1].shape == (72, 96, 5)
    assert leftovers(out) == []


def _failing_write(fail_at, make_error):
    """write_exr that raises (or breaks the directory) at the fail_at-th frame."""
    import raycore.images.image_io
    real = raycore.images.image_io.write_exr
    calls = []

    def write(path, *a, **kw):
        calls.append(path)
        if len(calls) == fail_at:
            make_error(Path(path))
        return real(path, *a, **kw)
    return write


@pytest.mark.parametrize("fault", ["ENOSPC", "EIO", "directory removed", "directory read-only"])
def test_io_faults_name_the_frame_and_keep_earlier_frames(tmp_path, monkeypatch, fault):
    import shutil
    import anim.render.job
    import anim.render.renderer

    def make_error(path):
        if fault in ("ENOSPC", "EIO"):
            code = getattr(errno, fault)
            raise OSError(code, os.strerror(code))
        if fault == "directory removed":
            shutil.rmtree(path.parent)
        else:
            path.parent.chmod(0o500)

    if fault == "directory read-only" and os.geteuid() == 0:
        pytest.skip("root writes into read-only directories")
    monkeypatch.setattr(anim.render.job, "write_exr", _failing_write(4, make_error))
    out = tmp_path / "out"
    res = CliRunner().invoke(main, ["render", str(DEMO), "-o", str(out), *ARGS])
    assert res.exit_code == 1, res.output
    line = res.output.strip().splitlines()[-1]
    assert "cannot write frame 3" in line and "internal error" not in line, line
    if fault != "directory removed":
        out.chmod(0o755)
        assert [p.name for p in exr_frames(out)] == [f"frame_000{i}.exr" for i in range(3)]
        assert leftovers(out) == []
        stats = json.loads((out / "stats.json").read_text())
        assert [f["frame"] for f in stats["frames"]] == [0, 1, 2]
        assert stats["runs"][-1]["ended"].startswith("failed")


def test_two_resume_renders_into_one_directory_share_the_frames(tmp_path, reference):
    out = tmp_path / "out"
    procs = [forked(tmp_path / "logs", "render", DEMO, "-o", out, "--resume", *ARGS) for _ in range(2)]
    for p in procs:
        assert p.wait(timeout=300) == 0, p.stderr.read()
    assert [p.name for p in exr_frames(out)] == [p.name for p in exr_frames(reference)]
    for p in exr_frames(out):
        np.testing.assert_array_equal(pixels(p)[1], pixels(reference / p.name)[1])
    stats = json.loads((out / "stats.json").read_text())
    rendered = [r["frames_rendered"] for r in stats["runs"]]
    assert len(rendered) == 2 and sum(rendered) == N_FRAMES      # no frame rendered twice
    assert [f["frame"] for f in stats["frames"]] == list(range(N_FRAMES))
    assert leftovers(out) == []


def test_a_claim_of_a_dead_process_does_not_block(tmp_path):
    from anim.render.output_dir import claim, claim_path, release
    frame = tmp_path / "frame_0001.exr"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    import socket
    claim_path(frame).write_text(f"{socket.gethostname()} {dead.pid} 0\n")
    assert claim(frame)                    # taken over
    assert not claim(frame) or claim_path(frame).read_text().split()[1] == str(os.getpid())
    release(frame)
    assert not claim_path(frame).exists()


def test_a_write_probe_left_by_a_kill_is_removed_by_the_next_run(tmp_path, monkeypatch):
    """The probe that checks a directory is writable is named like the other
    temporaries: killed between its creation and its removal (found by the
    kill loop above), the next run removes it."""
    import tempfile
    from anim.render.output_dir import remove_stale_temps
    from anim.render.paths import writable_dir
    made = []
    real_mkstemp = tempfile.mkstemp

    def mkstemp_and_die(*args, **kw):          # the kill, right after the probe exists
        fd, path = real_mkstemp(*args, **kw)
        made.append(path)
        raise KeyboardInterrupt
    monkeypatch.setattr(tempfile, "mkstemp", mkstemp_and_die)
    with pytest.raises(KeyboardInterrupt):
        writable_dir(tmp_path, "frames")
    monkeypatch.setattr(tempfile, "mkstemp", real_mkstemp)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    probe = Path(made[0])
    left = probe.with_name(probe.name.replace(f".{os.getpid()}.tmp", f".{dead.pid}.tmp"))
    probe.rename(left)                         # as if its process were the dead one
    assert remove_stale_temps(tmp_path) == [left.name]
    assert list(tmp_path.iterdir()) == []


def test_memory_stays_flat_over_a_long_render(tmp_path):
    """2,000 frames at 64^2: resident memory after the last is within 5% of
    that after frame 100 (buffers, grids and stats rows do not pile up)."""
    from anim.scene import AnimatedScene
    from anim.render.job import RenderJob, render_animation
    from anim.render.settings import config_of
    text = DEMO.read_text().replace("end: 47", "end: 1999")
    scene_path = tmp_path / "anim.yaml"
    scene_path.write_text(text)
    for f in DEMO.parent.iterdir():
        if f.name != "anim.yaml":
            (tmp_path / f.name).symlink_to(f)
    scene = AnimatedScene(scene_path)
    cfg = config_of(scene, width=64, height=64, threads=0)
    rss = {}

    def on_frame(row):
        if row["frame"] in (100, 1999):
            with open("/proc/self/statm") as f:
                rss[row["frame"]] = int(f.read().split()[1]) * resource.getpagesize()
    render_animation(RenderJob(scene, cfg, scene.frame_numbers, tmp_path / "out", tmp_path / "out" / "stats.json",
                               False, False), on_frame)
    assert abs(rss[1999] - rss[100]) <= 0.05 * rss[100], rss


def test_a_second_ctrl_c_stops_at_once_and_still_leaves_no_broken_file(tmp_path):
    from anim.render.output_dir import whole_frame
    out = tmp_path / "out"
    proc = frustrace("render", DEMO, "-o", out, *ARGS)
    while proc.poll() is None and (len(exr_frames(out)) if out.exists() else 0) < 2:
        time.sleep(0.002)
    proc.send_signal(signal.SIGINT)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=60) == 130
    assert all(whole_frame(p, 96, 72, "RGBAZ") == "" for p in exr_frames(out))
    assert leftovers(out) == []


def test_a_render_that_would_not_fit_in_memory_is_refused_with_the_estimate(tmp_path, monkeypatch):
    import anim.render.job
    import anim.render.renderer
    res = CliRunner().invoke(main, ["render", str(DEMO), "-o", str(tmp_path / "huge"), "--res", "16384x16384", "-q"])
    if anim.render.renderer.available_bytes() and anim.render.renderer.available_bytes() < 60 * 1024 ** 3:
        assert res.exit_code == 2 and "GiB of work memory" in res.output, res.output
    # a normal frame on a machine that has (pretended) 50 MB left: refused
    # before anything is made (no folder, no stats.json), naming the option
    # the size came from
    monkeypatch.setattr(anim.render.renderer, "available_bytes", lambda: 50 * 1024 ** 2)
    res = CliRunner().invoke(main, ["render", str(DEMO), "-o", str(tmp_path / "out"), "--res", "1024x1024", "-q"])
    assert res.exit_code == 2 and ": --res: 1024x1024" in res.output and "50 MiB are available" in res.output
    assert not (tmp_path / "out").exists()
    res = CliRunner().invoke(main, ["render", str(DEMO), "-o", str(tmp_path / "out"), "-q"])
    assert res.exit_code == 2 and ": output.resolution: " in res.output and not (tmp_path / "out").exists()
    monkeypatch.setattr(anim.render.renderer, "available_bytes", lambda: 8 * 1024 ** 3)
    res = CliRunner().invoke(main, ["render", str(DEMO), "-o", str(tmp_path / "ok"), "--res", "64x48",
                                    "--frames", "0:0", "-q"])
    assert res.exit_code == 0, res.output


def test_symlinks_in_the_output_directory_are_replaced_not_followed(tmp_path):
    victim = tmp_path / "precious.exr"
    victim.write_bytes(b"someone else's file")
    out = tmp_path / "out"
    out.mkdir()
    (out / "frame_0000.exr").symlink_to(victim)
    (out / "stats.json").symlink_to(tmp_path / "precious.json")
    res = CliRunner().invoke(main, ["render", str(DEMO), "-o", str(out), "--frames", "0:0", "--res", "16x12",
                                    "--overwrite", "-q"])
    assert res.exit_code == 0, res.output
    assert victim.read_bytes() == b"someone else's file" and not (tmp_path / "precious.json").exists()
    assert not (out / "frame_0000.exr").is_symlink() and not (out / "stats.json").is_symlink()


def test_ctrl_c_in_bench_says_nothing_about_frames(tmp_path):
    # one thread: the check is of what Ctrl-C prints, and the other core runs other tests
    proc = frustrace("bench", "--scene", "demo", "--res", "2048", "--frames", "2000", "--packet", "8",
                     "--threads", "1")
    time.sleep(4)                              # well inside its minutes of frames
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=60) == 130
    err = proc.stderr.read()
    assert "interrupted" in err and "frame" not in err and "Traceback" not in err, err


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143)])
def test_the_longest_range_starts_at_once_and_stops_within_a_second(tmp_path, sig, code):
    """Issue 20: --frames 0:9999999 (the documented maximum) spent minutes
    planning, a stat per frame, with the signal handlers already waiting
    for the frame loop: SIGTERM at 120 s exited at 322 s with nothing
    written. Now the plan is lazy: the first frames come at once, the
    signal acts at the next frame, and stats.json reads the directory once."""
    out = tmp_path / "out"
    proc = frustrace("render", DEMO, "-o", out, "--frames", "0:9999999", "--res", "16x16", "-q")
    t0 = time.monotonic()
    while proc.poll() is None and (len(exr_frames(out)) if out.exists() else 0) < 3 and time.monotonic() - t0 < 240:
        time.sleep(0.01)
    assert len(exr_frames(out)) >= 3, proc.stderr.read()
    sent = time.monotonic()
    proc.send_signal(sig)
    assert proc.wait(timeout=60) == code
    assert time.monotonic() - sent < 5
    stats = json.loads((out / "stats.json").read_text())
    assert [f["frame"] for f in stats["frames"]] == [int(p.stem[-4:]) for p in exr_frames(out)]
    # --resume over the same range skips what is there, as lazily
    proc = frustrace("render", DEMO, "-o", out, "--frames", "0:9999999", "--res", "16x16", "-q", "--resume")
    n_before = len(exr_frames(out))
    while proc.poll() is None and len(exr_frames(out)) < n_before + 2:
        time.sleep(0.01)
    proc.send_signal(sig)
    assert proc.wait(timeout=60) == code
    stats = json.loads((out / "stats.json").read_text())
    assert len(stats["frames"]) == len(exr_frames(out)) > n_before


def test_an_interrupt_before_any_frame_says_nothing_was_written(tmp_path, monkeypatch):
    """Issue 20: the message said frames were "listed in stats.json" though
    no output folder had been made."""
    import anim.render.job

    def interrupted(*a, **kw):
        raise KeyboardInterrupt()
    monkeypatch.setattr(anim.render.job, "render_animation", interrupted)
    res = CliRunner().invoke(main, ["render", str(DEMO), "-o", str(tmp_path / "never"), "--res", "16x16", "-q"])
    assert res.exit_code == 130
    assert "nothing was written" in res.output and "stats.json" not in res.output
    assert not (tmp_path / "never").exists()


@pytest.mark.parametrize("stats_kept", [True, False], ids=["checksum", "decode"])
def test_resume_renders_again_a_frame_with_bytes_flipped_in_its_middle(tmp_path, stats_kept):
    """Issue 20: 64 bytes flipped in the middle of a finished frame (same
    size, header and last scanline intact) were kept by --resume, though no
    reader could decode the frame. With stats.json, its checksum finds it;
    without (a killed run's frame), a full decode does."""
    out = tmp_path / "out"
    args = ["render", str(DEMO), "-o", str(out), "--frames", "0:2", "--res", "256x192", "-q"]
    assert CliRunner().invoke(main, args).exit_code == 0
    stats = json.loads((out / "stats.json").read_text())
    assert all(isinstance(r["crc32"], int) for r in stats["frames"])
    victim = out / "frame_0001.exr"
    data = bytearray(victim.read_bytes())
    mid = len(data) // 2
    data[mid:mid + 64] = bytes(b ^ 0xFF for b in data[mid:mid + 64])
    victim.write_bytes(bytes(data))
    if not stats_kept:
        (out / "stats.json").unlink()
    untouched = {p.name: p.stat().st_mtime_ns for p in exr_frames(out) if p != victim}
    res = CliRunner().invoke(main, args + ["--resume"])
    assert res.exit_code == 0, res.output
    warned = [line for line in res.output.splitlines() if "frame_0001.exr" in line]
    assert len(warned) == 1 and "rendering frame 1 again" in warned[0], res.output
    assert ("checksum" in warned[0]) == stats_kept
    assert {p.name: p.stat().st_mtime_ns for p in exr_frames(out) if p != victim} == untouched
    assert pixels(victim)[1].shape == (192, 256, 5)
    # frames decoded whole keep their checksum now: the next --resume compares it
    stats = json.loads((out / "stats.json").read_text())
    assert all(isinstance(r.get("crc32"), int) for r in stats["frames"]), stats["frames"]


def test_a_second_scene_into_the_same_stats_is_refused_with_the_owner_named(tmp_path):
    """Issue 20: two scenes rendered into one folder kept one frame-0 entry
    (the second scene's) and switched stats.json's scene silently."""
    import shutil
    other_dir = tmp_path / "other"
    shutil.copytree(DEMO.parent, other_dir)
    other = other_dir / "other.yaml"
    other.write_text((other_dir / "anim.yaml").read_text().replace("out/frame_####.exr", "out/other_####.exr"))
    out = tmp_path / "out"
    first = CliRunner().invoke(main, ["render", str(DEMO), "-o", str(out), "--frames", "0:0", "--res", "24x16", "-q"])
    assert first.exit_code == 0
    before = (out / "stats.json").read_text()
    res = CliRunner().invoke(main, ["render", str(other), "-o", str(out), "--frames", "0:0", "--res", "24x16", "-q"])
    assert res.exit_code == 2 and "another scene" in res.output and "anim.yaml" in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1
    assert (out / "stats.json").read_text() == before and not (out / "other_0000.exr").exists()
    res = CliRunner().invoke(main, ["render", str(other), "-o", str(out), "--frames", "0:0", "--res", "24x16", "-q",
                                    "--stats", str(tmp_path / "other-stats.json")])
    assert res.exit_code == 0 and (out / "other_0000.exr").exists()


def test_many_stale_claims_are_one_warning(tmp_path):
    """Issue 20: resume after a killed --workers render printed one warning
    per stale claim (18 lines)."""
    import socket
    out = tmp_path / "out"
    out.mkdir()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    for f in range(6):
        (out / f".frame_{f:04d}.exr.claim").write_text(f"{socket.gethostname()} {dead.pid} 0\n")
    res = CliRunner().invoke(main, ["render", str(DEMO), "-o", str(out), "--frames", "0:5", "--res", "24x16",
                                    "-q", "--resume"])
    assert res.exit_code == 0, res.output
    warned = [line for line in res.output.splitlines() if "removed" in line]
    assert len(warned) == 1 and "6 claims" in warned[0], res.output
    assert leftovers(out) == [] and len(exr_frames(out)) == 6


def test_a_resume_with_nothing_left_to_render_removes_a_dead_claim(tmp_path):
    """A render killed after its last frame was in place but before it
    released that frame's claim (seen once in the kill loop above): the
    next --resume has no frame to render and still removes the claim."""
    import socket
    out = tmp_path / "out"
    args = ["render", str(DEMO), "-o", str(out), "--frames", "0:1", "--res", "24x16", "-q"]
    assert CliRunner().invoke(main, args).exit_code == 0
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (out / ".frame_0001.exr.claim").write_text(f"{socket.gethostname()} {dead.pid} 0\n")
    res = CliRunner().invoke(main, args + ["--resume"])
    assert res.exit_code == 0, res.output
    assert leftovers(out) == [] and len(exr_frames(out)) == 2
    assert "removed" in res.output


def test_a_summary_of_recovered_frames_only_has_an_unknown_median_write():
    """Every frame recovered from killed runs (write time unknown): the
    summary's median write is null, not 0 (the SIGKILL test above reaches
    this when its last run finds every frame on disk); the table prints '-'."""
    from anim.render.stats import summarize
    from cli.report import summary_table
    row = {"interp_ms": 0.1, "build_ms": 1.0, "trace_ms": 5.0, "shade_ms": 9.0, "shadow_ms": 8.0}
    summary = summarize([{**row, "write_ms": None}] * 3, 1.0, 0.0)
    assert summary["median_ms"]["write_ms"] is None and summary["median_ms"]["trace_ms"] == 5.0
    mixed = summarize([{**row, "write_ms": None}, {**row, "write_ms": 30.0}], 1.0, 0.0)
    assert mixed["median_ms"]["write_ms"] == 30.0
    summary_table({"summary": summary, "scene": "s", "resolution": [8, 8], "packet": 8, "threads": 1,
                   "frames": [0, 1, 2], "runs": []})
