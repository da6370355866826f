"""cli.main.entry, the `frustrace` command: it skips the interpreter's
teardown (os._exit), so it must still end with main's exit status and with
everything printed."""
import subprocess
import sys

from conftest import ROOT


def _run(body):
    code = "import sys; sys.path.insert(0, %r)\nimport cli.main as m\n%s\nm.entry()\n" % (str(ROOT), body)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)


def test_the_exit_status_is_mains():
    assert _run("m.main = lambda: print('done')").returncode == 0
    assert _run("def f(): raise SystemExit(2)\nm.main = f").returncode == 2
    assert _run("def f(): raise SystemExit(None)\nm.main = f").returncode == 0
    said = _run("def f(): raise SystemExit('cannot go on')\nm.main = f")
    assert said.returncode == 1 and "cannot go on" in said.stderr
    crashed = _run("def f(): raise RuntimeError('a bug')\nm.main = f")
    assert crashed.returncode == 1 and "RuntimeError: a bug" in crashed.stderr


def test_buffered_output_and_later_atexit_functions_are_not_lost():
    """Output still in the buffers of a pipe, and the atexit functions that
    libraries register after the command started, all come out."""
    res = _run("import atexit\n"
               "def f():\n"
               "    atexit.register(lambda: print('atexit ran', flush=True))\n"
               "    sys.stdout.write('x' * 100000 + 'end')\n"
               "m.main = f")
    assert res.returncode == 0
    assert res.stdout.startswith("x" * 100000 + "end") and "atexit ran" in res.stdout


def test_the_command_renders_and_reports_with_its_exit_codes(tmp_path):
    ok = subprocess.run([sys.executable, "-m", "cli.main", "render", str(ROOT / "anim/builtin/demo/anim.yaml"),
                         "-o", str(tmp_path), "--frames", "0:0", "--res", "32x32"],
                        capture_output=True, text=True, cwd=ROOT)
    assert ok.returncode == 0 and "fps_full" in ok.stdout and (tmp_path / "stats.json").exists()
    bad = subprocess.run([sys.executable, "-m", "cli.main", "render", str(tmp_path / "none.yaml")],
                         capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 2 and bad.stderr.startswith("frustrace: error:")
