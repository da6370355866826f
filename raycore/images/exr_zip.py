"""ZIP-compressed scanline OpenEXR frames, encoded here instead of by the
OpenEXR library, because its deflate is most of a frame's write.

OpenEXR's `zip` codec (ZIP_COMPRESSION, and ZIPS with one scanline per
block) splits each block of 16 scanlines' bytes into even and odd bytes,
replaces every byte by its difference to the one before (+128), and
deflates the result as a zlib stream. The OpenEXR bindings deflate with
zlib at level 4 (and ignore the level asked for): 99-134 core-ms for a
whole write of a 1024^2 RGBA half + Z float frame. Here the same bytes are
laid out by a numba kernel (0.6 ms on one thread), predicted in numpy and
deflated with ISA-L (the `isal` package: Intel's deflate; at its level 1,
13 ms of one core for hand's frame against zlib's 95 at level 4 and 59 at
level 1, files ~8 % larger than the bindings'), the blocks on a thread
pool: 41 core-ms for the whole write. The file is a standard single-part
scanline OpenEXR file (OpenEXR file layout, "Technical Introduction" and
"OpenEXR File Layout" of openexr.com): every OpenEXR reader opens it, and
tests/raycore/test_exr_zip.py reads it back bit for bit through the OpenEXR
bindings and OpenImageIO.
"""
import os
import struct

import numpy as np
from isal import isal_zlib

from raycore.jit.presets import kernel
from raycore.jit.thread_pool import thread_pool

MAGIC = 20000630
VERSION = 2
LONG_NAMES = 0x400              # version flag: an attribute or channel name longer than 31 bytes
HALF, FLOAT = 1, 2              # OpenEXR pixel types
CODES = {"zip": (3, 16), "zips": (2, 1)}       # codec -> (compression attribute, scanlines per block)
LEVEL = 1                       # ISA-L's level 1: its levels 2 and 3 were no smaller here, and slower
TASKS = 64                      # deflate tasks per frame, for the thread pool


@kernel
def split_blocks(planar, ch_off, ch_row, height, lines, split):
    """Each block of `lines` scanlines' bytes split as OpenEXR's zip codec
    does before its predictor. planar: every channel's whole image, one
    after the other (channel c's row y at ch_off[c] + y * ch_row[c], ch_row[c]
    bytes, an even count). A block's raw bytes are its scanlines in order,
    each the channels' rows in order; `split` gets, at the block's offset
    y0 * line bytes, its bytes at even positions, then those at odd ones
    (the first (n + 1) // 2 = n // 2 bytes: n is even)."""
    line = 0
    for c in range(ch_off.shape[0]):
        line += ch_row[c]
    for blk in range((height + lines - 1) // lines):
        y0 = blk * lines
        y1 = min(y0 + lines, height)
        base = y0 * line
        half = (y1 - y0) * line // 2
        k = 0                        # the row's first position in the block's raw bytes: even
        for y in range(y0, y1):
            for c in range(ch_off.shape[0]):
                m = ch_row[c] // 2
                src = planar[ch_off[c] + y * ch_row[c]:ch_off[c] + (y + 1) * ch_row[c]]
                even = split[base + k // 2:base + k // 2 + m]
                odd = split[base + half + k // 2:base + half + k // 2 + m]
                for j in range(m):   # slices: LLVM vectorizes the strided copy (1 ms, not 17)
                    even[j] = src[2 * j]
                    odd[j] = src[2 * j + 1]
                k += ch_row[c]


def predicted(split: np.ndarray, block_starts) -> np.ndarray:
    """OpenEXR's zip predictor over every block: each byte but a block's
    first becomes (byte - previous + 128) mod 256. In numpy's uint8
    arithmetic, which wraps and vectorizes (a numba loop widened every byte
    to 64 bits and ran scalar, 17 ms against ~2)."""
    out = np.empty_like(split)
    np.subtract(split[1:], split[:-1], out=out[1:])
    out += np.uint8(128)
    out[block_starts] = split[block_starts]
    return out


def _attribute(name: str, kind: str, payload: bytes) -> bytes:
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(payload)) + payload


def _metadata_attribute(name: str, value) -> bytes:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise TypeError(f"EXR metadata {name!r}: int, float or str, not {type(value).__name__}")
    if isinstance(value, int):
        return _attribute(name, "int", struct.pack("<i", value))
    if isinstance(value, float):
        return _attribute(name, "float", struct.pack("<f", value))
    return _attribute(name, "string", value.encode())


def header(names_types, width: int, height: int, compression: int, metadata: dict) -> bytes:
    """Magic, version and the header attributes (sorted by name, as
    OpenEXR writes them) of a scanline image."""
    chlist = b"".join(name.encode() + b"\0" + struct.pack("<iB3xii", kind, 0, 1, 1) for name, kind in names_types)
    window = struct.pack("<iiii", 0, 0, width - 1, height - 1)
    attrs = {"channels": _attribute("channels", "chlist", chlist + b"\0"),
             "compression": _attribute("compression", "compression", bytes([compression])),
             "dataWindow": _attribute("dataWindow", "box2i", window),
             "displayWindow": _attribute("displayWindow", "box2i", window),
             "lineOrder": _attribute("lineOrder", "lineOrder", b"\0"),
             "pixelAspectRatio": _attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
             "screenWindowCenter": _attribute("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)),
             "screenWindowWidth": _attribute("screenWindowWidth", "float", struct.pack("<f", 1.0)),
             "type": _attribute("type", "string", b"scanlineimage")}
    for name, value in metadata.items():
        if name in attrs:
            raise ValueError(f"EXR metadata {name!r} is a standard attribute that the writer sets")
        attrs[name] = _metadata_attribute(name, value)
    names = [n for n, _ in names_types] + list(attrs)
    flags = LONG_NAMES if max(len(n.encode()) for n in names) > 31 else 0
    return (struct.pack("<ii", MAGIC, VERSION | flags) + b"".join(attrs[k] for k in sorted(attrs)) + b"\0")


def encode(channels: dict, metadata: dict, codec: str = "zip") -> list:
    """The bytes of a zip- (or zips-) compressed scanline EXR file, as a list
    of byte strings to write in order. channels: name -> (H, W) float16 or
    float32 array (a strided view is fine: it is copied once, into the
    planar layout the kernel reads), all of one size."""
    compression, lines = CODES[codec]
    names = sorted(channels)
    arrays = [channels[n] for n in names]
    height, width = arrays[0].shape
    for name, a in zip(names, arrays):
        if a.shape != (height, width) or a.dtype not in (np.float16, np.float32):
            raise ValueError(f"EXR channel {name!r}: a ({height}, {width}) float16 or float32 array, "
                             f"not {a.shape} {a.dtype}")
    row = np.array([a.dtype.itemsize * width for a in arrays], np.int64)
    off = np.zeros(len(arrays), np.int64)
    np.cumsum(row[:-1] * height, out=off[1:])
    planar = np.empty(int(row.sum()) * height, np.uint8)
    for a, o, r in zip(arrays, off, row):
        planar[o:o + r * height].view(a.dtype).reshape(height, width)[...] = a
    split = np.empty_like(planar)
    split_blocks(planar, off, row, height, lines, split)
    line = int(row.sum())
    starts = range(0, height, lines)
    predicted_bytes = predicted(split, np.arange(0, height, lines, dtype=np.int64) * line)

    def deflate(y0):
        y1 = min(y0 + lines, height)
        packed = isal_zlib.compress(memoryview(predicted_bytes)[y0 * line:y1 * line], LEVEL)
        # a block that deflate cannot shrink is stored as it is, unpredicted (OpenEXR's rule)
        return packed if len(packed) < (y1 - y0) * line else planar_block(planar, off, row, y0, y1)

    # tasks of several blocks (zips has one per scanline: a task each cost more than its deflate)
    per_task = max(1, len(starts) // TASKS)
    tasks = [starts[i:i + per_task] for i in range(0, len(starts), per_task)]
    pool = thread_pool("exr-deflate", os.cpu_count() or 1)
    blocks = [b for done in pool.map(lambda task: [deflate(y0) for y0 in task], tasks) for b in done]
    head = header([(n, HALF if a.dtype == np.float16 else FLOAT) for n, a in zip(names, arrays)],
                  width, height, compression, metadata)
    offsets = np.empty(len(blocks), np.uint64)
    pos = len(head) + 8 * len(blocks)
    chunks = []
    for i, (y0, data) in enumerate(zip(starts, blocks)):
        offsets[i] = pos
        chunks += [struct.pack("<ii", y0, len(data)), data]
        pos += 8 + len(data)
    return [head, offsets.tobytes(), *chunks]


def planar_block(planar, off, row, y0, y1) -> bytes:
    """Scanlines y0..y1-1 as raw bytes (each line the channels' rows in order)."""
    return b"".join(planar[off[c] + y * row[c]:off[c] + (y + 1) * row[c]].tobytes()
                    for y in range(y0, y1) for c in range(len(off)))
