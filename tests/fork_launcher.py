"""frustrace renders in processes forked from a server that has already
imported it, for tests that start many processes only to kill them.

A fresh `python -m cli.main` spends ~0.9 s of CPU before its first frame:
importing numba, numpy and frustrace, and numba's own first set-up when it
loads a cached kernel (its lowering registries, its check for a BLAS). The
SIGKILL test starts 21 renders; forked from multiprocessing's forkserver,
which does those imports once (nothing in them starts a thread, so the
fork is safe), a render of the demo's 40 frames at 96x72 takes 0.3 s
instead of 1.0 s, and the test 3.3 s instead of 16. The child is a process of its own:
its own threads, files and exit status, killed by a real SIGKILL. Tests of
what a fresh process does (the entry point, Ctrl-C, start-up time, imports)
keep starting `python -m cli.main`."""
import io
import itertools
import multiprocessing
import os
import signal
from multiprocessing import forkserver
from pathlib import Path

# what the server imports once (it imports this module): the command, the
# renderer, and numba's registries, set up as its first kernel load would
import anim.render.job  # noqa: F401
import cli.main  # noqa: F401
import numba.np.arraymath  # noqa: F401  (numba's check for a BLAS)
from numba.core.registry import cpu_target

cpu_target.target_context.refresh()
cpu_target.typing_context.refresh()

PRELOAD = [__name__]
_context = None
_serial = itertools.count()


def _cli(argv, cwd, out_path, err_path):
    """The child: the standard streams into files, SIGINT as a fresh
    interpreter has it, then the command (its SystemExit is the exit status)."""
    os.chdir(cwd)
    for fd, path in ((1, out_path), (2, err_path)):
        f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(f, fd)
        os.close(f)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    from cli.main import main
    main(argv, prog_name="frustrace")


def _start_server():
    """The forkserver, with this directory on its PYTHONPATH for the
    preload: Python 3.11's server is given the parent's sys.path but does
    not use it, and skips a preload it cannot import without a word."""
    saved = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).parent)] + ([saved] if saved else []))
    try:
        forkserver.ensure_running()
    finally:
        if saved is None:
            del os.environ["PYTHONPATH"]
        else:
            os.environ["PYTHONPATH"] = saved


class Forked:
    """The part of subprocess.Popen the tests use: poll, send_signal, wait,
    pid, and stderr as a file to read."""

    def __init__(self, args, cwd, log_dir: Path):
        global _context
        if _context is None:
            _context = multiprocessing.get_context("forkserver")
            _context.set_forkserver_preload(PRELOAD)
            _start_server()
        log_dir.mkdir(parents=True, exist_ok=True)
        n = next(_serial)
        out, err = log_dir / f"{n}.out", log_dir / f"{n}.err"
        self.process = _context.Process(target=_cli, args=([str(a) for a in args], str(cwd), str(out), str(err)))
        self.process.start()
        self.pid = self.process.pid
        self._err = err

    def poll(self):
        return self.process.exitcode

    def send_signal(self, sig):
        if self.process.exitcode is None:
            os.kill(self.pid, sig)

    def wait(self, timeout=None):
        self.process.join(timeout)
        if self.process.exitcode is None:
            raise TimeoutError(f"frustrace (pid {self.pid}) still running after {timeout} s")
        return self.process.exitcode

    @property
    def stderr(self):
        """What the child wrote to its standard error so far, as a file to
        read (read here, so that no file handle is left open)."""
        return io.StringIO(self._err.read_text(encoding="utf-8", errors="replace"))


__all__ = ["Forked"]
