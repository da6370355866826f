"""Vertex keyframes kept as they are read: one float32 array per key (12
bytes per vertex and key), interpolated linearly by a kernel, with no
float64 copy and no per-segment coefficients (anim/interpolate.Curve keeps
both, 32 bytes per vertex and segment more, for the smooth methods).

Past KEY_BUDGET bytes of keys, they are written to a file as they are read
and read back when a frame needs them (the two of its segment, a few kept):
a mesh with a hundred keys renders in the memory of a mesh with three."""
import os
import tempfile
from collections import OrderedDict

import numpy as np

from anim.interpolate import locate
from anim.vertex_kernels import lerp_into

KEY_BUDGET = 1 << 30         # bytes of keys kept in memory; more go to a file
KEPT = 3                     # keys read back from the file and kept at once


class KeyStore:
    """The keys of one object, in memory or in a file beside the others."""

    def __init__(self, budget=None):
        self.budget, self.shape = KEY_BUDGET if budget is None else budget, None
        self.keys, self.file, self.kept = [], None, OrderedDict()
        self.count = 0

    @property
    def nbytes(self):
        return self.count * int(np.prod(self.shape)) * 4 if self.shape else 0

    def add(self, vertices):
        v = np.ascontiguousarray(vertices, np.float32)
        self.shape = self.shape or v.shape
        self.count += 1
        if self.file is None and self.nbytes > self.budget:
            self._spill()
        if self.file is None:
            self.keys.append(v)
        else:
            self.file.seek(0, os.SEEK_END)
            self.file.write(v.tobytes())

    def _spill(self):
        """Move the keys kept so far into an unnamed temporary file."""
        self.file = tempfile.TemporaryFile(dir=os.environ.get("FRUSTRACE_SPILL_DIR"))
        for v in self.keys:
            self.file.write(v.tobytes())
        self.keys = []

    def __getitem__(self, k):
        if self.file is None:
            return self.keys[k]
        if k in self.kept:
            self.kept.move_to_end(k)
            return self.kept[k]
        size = int(np.prod(self.shape)) * 4
        self.file.seek(k * size)
        v = np.frombuffer(self.file.read(size), np.float32).reshape(self.shape)
        self.kept[k] = v
        while len(self.kept) > KEPT:
            self.kept.popitem(last=False)
        return v


class LinearKeys:
    """Linear interpolation of vertex keys: p0 + (p1 - p0) u in float64,
    the keys themselves returned exactly."""
    method = "linear"

    def __init__(self, times, store, extrapolate="clamp", constant=False):
        self.times = np.asarray(times, np.float64)
        self.store, self.extrapolate, self.constant = store, extrapolate, constant

    @property
    def nbytes(self):
        return self.store.nbytes

    def eval_into(self, t, out):
        if len(self.times) == 1:
            out[...] = self.store[0]
            return
        t, k = locate(self.times, t, self.extrapolate)
        if t >= self.times[-1]:
            out[...] = self.store[len(self.times) - 1]
            return
        u = (t - self.times[k]) / (self.times[k + 1] - self.times[k])
        if u == 0.0:
            out[...] = self.store[k]
            return
        lerp_into(self.store[k].reshape(-1), self.store[k + 1].reshape(-1), u, out.reshape(-1))
