"""What numba compiles during a run, and for how long: a listener on numba's
"numba:compile" events (fired on a cache miss only, so a warm run records
nothing). The command line shows a line while a first run compiles, and
stats.json lists the kernels compiled with their seconds."""
import threading
import time
from contextlib import contextmanager

from numba.core import event


class CompileWatch(event.Listener):
    """Top-level compiles (a kernel, with the helpers it compiles inside it)
    as (name, seconds), in order; `current` is the one compiling now."""

    def __init__(self, on_change=None):
        self.done = []               # [(qualified name, seconds)] of top-level compiles
        self._stack = []             # (name, start) of the compiles in progress, outermost first
        self._lock = threading.Lock()
        self.on_change = on_change or (lambda watch: None)

    @staticmethod
    def _name(ev):
        disp = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
        fn = getattr(disp, "py_func", None)
        return f"{fn.__module__}.{fn.__qualname__}" if fn is not None else "?"

    def on_start(self, ev):
        with self._lock:
            self._stack.append((self._name(ev), time.perf_counter()))
        self.on_change(self)

    def on_end(self, ev):
        with self._lock:
            if not self._stack:
                return
            name, t0 = self._stack.pop()
            if not self._stack:
                self.done.append((name, time.perf_counter() - t0))
        self.on_change(self)

    @property
    def current(self):
        with self._lock:
            return self._stack[0][0] if self._stack else None

    def seconds(self) -> dict:
        """{kernel: seconds} of the top-level compiles (summed per kernel)."""
        out = {}
        for name, s in self.done:
            out[name] = out.get(name, 0.0) + s
        return {k: round(v, 3) for k, v in out.items()}


@contextmanager
def watching(on_change=None):
    """Record the compiles of the block: yields the CompileWatch."""
    watch = CompileWatch(on_change)
    event.register("numba:compile", watch)
    try:
        yield watch
    finally:
        event.unregister("numba:compile", watch)
