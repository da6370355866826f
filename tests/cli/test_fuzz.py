"""Hostile input: scene files mutated from the demo's (wrong types, missing
and unknown keys, extreme numbers, NaN and inf, huge lists, deep nesting,
unicode, YAML aliases) and random bytes in the mesh, texture, weights and
glTF files it names. The only outcomes allowed: a clean run, or exit 2 with
one line. Never an internal error (exit 1), a traceback, a hang past the
alarm, or a frame written from a rejected scene.

Bounded in `make test`; FRUSTRACE_FUZZ_EXAMPLES=2000 runs more."""
import copy
import math
import os
import shutil
import signal
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import yaml
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cli.main import main
from gltf_files import GltfBuilder

DEMO = Path(__file__).resolve().parents[2] / "anim" / "builtin" / "demo"
EXAMPLES = int(os.environ.get("FRUSTRACE_FUZZ_EXAMPLES", "60"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
ALARM_S = 30

BASE = yaml.safe_load((DEMO / "anim.yaml").read_text())
BASE["output"] = {"path": "out/f_####.exr", "resolution": [24, 16]}
BASE["frames"] = {"start": 0, "end": 2, "fps": 24}
BASE["objects"].append({"name": "arm", "mesh": "ball.obj",
                        "skeleton": {"weights": "w.npz", "joints": [
                            {"name": "root", "angles": {"keys": [[0, 0, 0, 0], [1, 0, 40, 0]]}},
                            {"name": "tip", "parent": "root", "origin": [0, 1, 0]}]}})
BASE["objects"].append({"name": "rig", "mesh": "rig.glb"})

JUNK = [None, True, -1, 0, 7, 10 ** 30, -1e308, 1e-300, math.nan, math.inf, -math.inf, "", "∞ü\u202e",
        "x" * 5000, [], {}, [[1, 2, 3]], {"a": {"b": {"c": 1}}}, [0.0] * 20000, "../../../etc/passwd",
        "ball.obj", "#####.exr"]


class Timeout(Exception):
    pass


@contextmanager
def alarm(seconds):
    def ring(signum, frame):
        raise Timeout(f"no answer within {seconds} s")
    before = signal.signal(signal.SIGALRM, ring)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, before)


def scene_dir(tmp: Path) -> Path:
    """The demo's files plus skin weights and a small animated glTF."""
    for f in DEMO.iterdir():
        if f.name != "anim.yaml":
            shutil.copy(f, tmp / f.name)
    n = sum(1 for line in (DEMO / "ball.obj").read_text().splitlines() if line.startswith("v "))
    np.savez(tmp / "w.npz", joints=np.stack([np.zeros(n, int), np.ones(n, int)], 1),
             weights=np.full((n, 2), 0.5))
    b = GltfBuilder()
    mesh = b.mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), [0, 1, 2])
    node = b.node(mesh=mesh)
    b.animation([(node, "translation", [0.0, 1.0], np.array([[0, 0, 0], [0, 1, 0]], np.float32), "LINEAR")])
    b.save(tmp / "rig.glb", [node])
    return tmp


def paths_in(tree, prefix=()):
    """Every path (tuple of keys/indices) into the nested scene dict."""
    yield prefix
    if isinstance(tree, dict):
        for k, v in tree.items():
            yield from paths_in(v, prefix + (k,))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            yield from paths_in(v, prefix + (i,))


def deep(n):
    v = 1
    for _ in range(n):
        v = [v]
    return v


def mutate(tree, data):
    """One random change: replace, delete, add an unknown key, nest deeply, or
    duplicate a subtree, at a random place."""
    tree = copy.deepcopy(tree)
    targets = [p for p in paths_in(tree) if p]
    path = data.draw(st.sampled_from(targets))
    parent = tree
    for k in path[:-1]:
        parent = parent[k]
    key = path[-1]
    kind = data.draw(st.sampled_from(["replace", "delete", "unknown", "nest", "copy", "number"]))
    if kind == "replace":
        parent[key] = data.draw(st.sampled_from(JUNK))
    elif kind == "delete":
        del parent[key]
    elif kind == "unknown" and isinstance(parent, dict):
        parent[data.draw(st.text(min_size=1, max_size=8))] = 1
    elif kind == "nest":
        parent[key] = deep(data.draw(st.integers(5, 200)))
    elif kind == "copy":
        parent[key] = copy.deepcopy(tree)
    elif kind == "number":
        parent[key] = data.draw(st.floats(allow_nan=True, allow_infinity=True) | st.integers(-2 ** 70, 2 ** 70))
    return tree


def assert_clean(res, out_dir: Path):
    assert res.exit_code in (0, 2), res.output
    if res.exit_code == 2:
        lines = res.output.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("frustrace: error: "), res.output
        assert not out_dir.exists() or not list(out_dir.glob("*.exr"))
    assert "Traceback" not in res.output and "internal error" not in res.output, res.output


@FUZZ
@given(data=st.data())
def test_mutated_scene_files_are_rendered_or_rejected_in_one_line(tmp_path_factory, data):
    tmp = scene_dir(tmp_path_factory.mktemp("fuzz"))
    tree = mutate(BASE, data)
    if data.draw(st.booleans()):
        tree = mutate(tree, data)
    path = tmp / "anim.yaml"
    with alarm(ALARM_S):
        path.write_text(yaml.safe_dump(tree, allow_unicode=True))
        res = CliRunner().invoke(main, ["check", str(path)])
        assert_clean(res, tmp / "out")
        if res.exit_code == 0:             # what check passes, render accepts
            res = CliRunner().invoke(main, ["render", str(path), "-o", str(tmp / "out"), "--frames", "0:0",
                                            "--res", "12x8", "-q"])
            assert res.exit_code == 0, res.output


@FUZZ
@given(data=st.data())
def test_yaml_that_is_not_a_scene_is_one_line(tmp_path_factory, data):
    tmp = tmp_path_factory.mktemp("text")
    text = data.draw(st.one_of(
        st.text(max_size=300),
        st.binary(max_size=300).map(lambda b: b.decode("latin-1")),
        st.just("a: &x [*x]\n"), st.just("a: !!python/object:os.system ls\n"),
        st.just("- " * 500 + "1\n"), st.just("{" * 300 + "}" * 300 + "\n"),
        st.just("x: &a [" + ", ".join(["*a"] * 3) + "]\n"),
    ))
    path = tmp / "anim.yaml"
    path.write_text(text, errors="surrogatepass") if isinstance(text, str) else path.write_bytes(text)
    with alarm(ALARM_S):
        assert_clean(CliRunner().invoke(main, ["check", str(path)]), tmp / "out")


@FUZZ
@given(data=st.data())
def test_random_bytes_in_the_files_a_scene_names(tmp_path_factory, data):
    tmp = scene_dir(tmp_path_factory.mktemp("files"))
    (tmp / "anim.yaml").write_text(yaml.safe_dump(BASE))
    victim = data.draw(st.sampled_from(["ball.obj", "floor.obj", "tube_002.obj", "checker.png", "w.npz", "rig.glb"]))
    original = (tmp / victim).read_bytes()
    how = data.draw(st.sampled_from(["random", "truncate", "flip"]))
    if how == "random":
        blob = data.draw(st.binary(max_size=4000))
    elif how == "truncate":
        blob = original[:data.draw(st.integers(0, len(original)))]
    else:
        pos = data.draw(st.lists(st.integers(0, max(len(original) - 1, 0)), min_size=1, max_size=20))
        b = bytearray(original)
        for p in pos:
            b[p] = data.draw(st.integers(0, 255))
        blob = bytes(b)
    (tmp / victim).write_bytes(blob)
    with alarm(ALARM_S):
        res = CliRunner().invoke(main, ["check", str(tmp / "anim.yaml")])
        assert_clean(res, tmp / "out")
        if res.exit_code == 0:
            res = CliRunner().invoke(main, ["render", str(tmp / "anim.yaml"), "-o", str(tmp / "out"),
                                            "--frames", "0:0", "--res", "12x8", "-q"])
            assert res.exit_code == 0, res.output
