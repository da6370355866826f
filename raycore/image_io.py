"""The one OpenImageIO module: EXR frames out (atomically), textures in.

Channels R G B A are stored as half, Z and AOVs as float32 (SPEC section 4).
OpenImageIO's Python binding takes one dtype per call, so the frame is handed
over as float32 and OpenImageIO converts RGBA to half while writing.
The file is written under a temporary name in the same directory and renamed,
so a killed render never leaves a half-written frame behind.
"""
import os

import numpy as np
import OpenImageIO as oiio

HALF_CHANNELS = ("R", "G", "B", "A")
# The render waits for the write (cli/pipeline.py), so the writer may use every
# core: measured 115-140 ms per 1024^2 RGBA-half + Z frame with 2 threads
# against 175-200 ms with one. (OpenImageIO's per-channel half/float path is
# its slow one; a 4-channel half write from float16 data takes ~30-40 ms.)
oiio.attribute("threads", 0)
oiio.attribute("exr_threads", 0)


def write_exr(path: str, channels: dict, metadata: dict) -> None:
    """channels: name -> (H, W) float32 array, in file order; R G B A first."""
    names = list(channels)
    height, width = next(iter(channels.values())).shape
    pixels = np.empty((height, width, len(names)), np.float32)
    for i, name in enumerate(names):
        pixels[:, :, i] = channels[name]
    spec = oiio.ImageSpec(width, height, len(names), "float")
    spec.channelnames = tuple(names)
    spec.channelformats = tuple(oiio.TypeDesc("half" if n in HALF_CHANNELS else "float")
                                for n in names)
    spec.attribute("compression", "zip")
    for key, value in metadata.items():
        spec.attribute(key, value)
    directory = os.path.dirname(os.path.abspath(path))
    tmp = os.path.join(directory, f".{os.path.basename(path)}.{os.getpid()}.tmp.exr")
    out = oiio.ImageOutput.create(tmp)
    if out is None:
        raise OSError(f"{path}: OpenImageIO cannot create an EXR writer: {oiio.geterror()}")
    try:
        if not (out.open(tmp, spec) and out.write_image(pixels)):
            raise OSError(f"{path}: {out.geterror()}")
        out.close()
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def read_exr(path: str):
    """(channel names, (H, W, C) float32 pixels, spec) — for tests and tools."""
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise OSError(f"{path}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        pixels = inp.read_image("float")
        return list(spec.channelnames), pixels, spec
    finally:
        inp.close()


def read_texture(path: str) -> np.ndarray:
    """(H, W, 3) float32 linear RGB of an image file (grey is replicated, alpha dropped)."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OSError(f"{path}: {oiio.geterror()}")
    try:
        pixels = inp.read_image("float")
    finally:
        inp.close()
    if pixels is None:
        raise OSError(f"{path}: cannot read pixels")
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    if pixels.shape[2] < 3:
        pixels = np.repeat(pixels[:, :, :1], 3, axis=2)
    return np.ascontiguousarray(pixels[:, :, :3], np.float32)


def _write_8bit(path: str, rgb: np.ndarray):
    out = oiio.ImageOutput.create(path)
    if out is None:
        raise OSError(f"{path}: {oiio.geterror()}")
    try:
        spec = oiio.ImageSpec(rgb.shape[1], rgb.shape[0], rgb.shape[2], "uint8")
        if not (out.open(path, spec) and out.write_image(np.ascontiguousarray(rgb))):
            raise OSError(f"{path}: {out.geterror()}")
    finally:
        out.close()


def write_texture(path: str, pixels: np.ndarray):
    """An 8-bit image file (PNG by extension) from (H, W, 3) values in [0, 1]."""
    _write_8bit(path, (np.clip(pixels, 0, 1) * 255 + 0.5).astype(np.uint8))


def exr_to_png(exr_path: str, png_path: str):
    """Tone-map a frame for previews: RGB over its background, clipped, sRGB encoded."""
    names, pixels, _ = read_exr(exr_path)
    rgb = np.clip(pixels[:, :, [names.index(c) for c in "RGB"]], 0.0, 1.0)
    srgb = np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * rgb ** (1 / 2.4) - 0.055)
    _write_8bit(png_path, (srgb * 255 + 0.5).astype(np.uint8))
