"""Work arrays kept from frame to frame.

A fresh array of a few MB costs a page fault per 4 KB page the first time it
is written (the kernel zero-fills it): ~25 ms per frame for the ~100 MB that
the surface, shadow and shading passes use at 1024^2. A Workspace hands out
C-contiguous views of buffers it keeps, grown when a frame needs more.
"""
from math import prod

import numpy as np


class Workspace:
    def __init__(self):
        self._buffers = {}

    def take(self, name: str, shape, dtype=np.float32, capacity: int = 0) -> np.ndarray:
        """An uninitialised C-contiguous array of `shape`; the same memory is
        handed out again for `name` on the next call (never two live uses).
        A new buffer holds at least `capacity` elements, so that a count that
        grows from frame to frame (visible pixels) does not reallocate."""
        # plain Python here: a pass takes a dozen arrays, and numpy's
        # atleast_1d/prod cost 9 us a call (small images, many passes)
        shape = tuple(map(int, shape)) if isinstance(shape, (tuple, list)) else (int(shape),)
        size = prod(shape)
        dtype = np.dtype(dtype)
        buf = self._buffers.get(name)
        if buf is None or buf.dtype != dtype or buf.size < size:
            buf = np.empty(max(size, capacity, 1), dtype)
            self._buffers[name] = buf
        return buf[:size].reshape(shape)


def scratch(workspace, name, shape, dtype=np.float32, capacity=0):
    """workspace.take, or a fresh array when there is no workspace."""
    if workspace is None:
        return np.empty(shape, dtype)
    return workspace.take(name, shape, dtype, capacity)
