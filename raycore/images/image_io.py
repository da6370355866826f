"""Image files at the edges: EXR frames out (OpenEXR), textures and previews
through OpenImageIO.

Frames in the zip and zips codecs (zip is the default) are encoded by
images/exr_zip.py: the same codec, deflated by ISA-L instead of zlib, for 2.4x
less CPU. The other codecs go through the official OpenEXR bindings: they
take a float16 array for R G B A and a float32 array for Z as they are,
where OpenImageIO's Python binding converts every channel one value at a
time (110-190 ms per 1024^2 frame against ~25 ms with the bindings).
Channels R G B A are half, Z and AOVs float32 (SPEC section 4). The file is written under a temporary name in the
same directory and renamed, so a killed render never leaves a half-written
frame behind.
"""
import os

import numpy as np
import OpenEXR
import OpenImageIO as oiio

from raycore.images import exr_zip
from raycore.images.half_float import to_half

HALF_CHANNELS = ("R", "G", "B", "A")
# output.compression -> OpenEXR's codec. "lossless" is as the OpenEXR docs
# state it; pxr24 rounds float32 channels (Z, AOVs) to 24 bits.
COMPRESSIONS = {
    "none": ("NO_COMPRESSION", "lossless"),
    "rle": ("RLE_COMPRESSION", "lossless"),
    "zips": ("ZIPS_COMPRESSION", "lossless"),
    "zip": ("ZIP_COMPRESSION", "lossless"),
    "piz": ("PIZ_COMPRESSION", "lossless"),
    "pxr24": ("PXR24_COMPRESSION", "lossy for float32 (Z, AOVs): 24-bit mantissa"),
    "b44": ("B44_COMPRESSION", "lossy for half"),
    "b44a": ("B44A_COMPRESSION", "lossy for half"),
    "dwaa": ("DWAA_COMPRESSION", "lossy"),
    "dwab": ("DWAB_COMPRESSION", "lossy"),
    "zstd": ("ZSTD_COMPRESSION", "lossless"),
    "htj2k256": ("HTJ2K256_COMPRESSION", "lossless"),
    "htj2k32": ("HTJ2K32_COMPRESSION", "lossless"),
}
COMPRESSIONS = {k: v for k, v in COMPRESSIONS.items() if hasattr(OpenEXR, v[0])}
# The render waits for the write (anim/render/job.py), so the codec may
# use every core: zip compresses in blocks of 16 scanlines in parallel.
OpenEXR.set_global_thread_count(os.cpu_count() or 1)
oiio.attribute("threads", 0)


def temp_path(path: str) -> str:
    """The name a frame is written under before it is renamed into place."""
    directory = os.path.dirname(os.path.abspath(path))
    return os.path.join(directory, f".{os.path.basename(path)}.{os.getpid()}.tmp.exr")


def write_exr(path: str, channels: dict, metadata: dict, compression: str = "zip") -> None:
    """channels: name -> (H, W) float32 array; R G B A are stored as half
    (given as one (H, W, 4) array under the key "RGBA", or apart), the rest
    as float32. Atomic: temporary file in the same directory, then rename."""
    if compression not in COMPRESSIONS:
        raise ValueError(f"unknown EXR compression {compression!r}; one of {', '.join(COMPRESSIONS)}")
    pixels = {}
    for name, values in channels.items():
        if name == "RGBA" or name in HALF_CHANNELS:
            pixels[name] = to_half(values)
        else:
            pixels[name] = np.ascontiguousarray(values, np.float32)
    tmp = temp_path(path)
    try:
        if compression in exr_zip.CODES:
            # the same codec as OpenEXR's, deflated by ISA-L: 2.4x fewer core-ms (images/exr_zip.py)
            planes = {}
            for name, values in pixels.items():
                if name == "RGBA":
                    planes.update((c, values[:, :, k]) for k, c in enumerate(HALF_CHANNELS))
                else:
                    planes[name] = values
            with open(tmp, "wb") as f:
                f.writelines(exr_zip.encode(planes, metadata, compression))
        else:
            header = {"compression": getattr(OpenEXR, COMPRESSIONS[compression][0]),
                      "type": OpenEXR.scanlineimage, **metadata}
            with OpenEXR.File(header, pixels) as exr:
                exr.write(tmp)
        os.replace(tmp, path)
    except RuntimeError as exc:          # the bindings raise RuntimeError on I/O errors
        raise OSError(f"{path}: {exc}") from None
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


def srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) undone, for values in [0, 1]."""
    v = np.asarray(values, np.float32)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(np.float32)


def read_texture(path: str, space: str = "auto") -> np.ndarray:
    """(H, W, 3) float32 linear RGB of an image file (grey is replicated).

    space "auto" decodes sRGB for integer formats (8- and 16-bit PNG, JPEG:
    colour images are sRGB-encoded by convention) and keeps float formats
    (EXR, HDR) as they are; "srgb" / "linear" force one or the other (data
    textures such as masks are linear). Alpha is dropped and never scales the
    colour: the surface is opaque, so the file's colour is read unassociated.
    """
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        raise OSError(f"{path}: {oiio.geterror()}")
    try:
        is_float = inp.spec().format.basetype in (oiio.FLOAT, oiio.HALF, oiio.DOUBLE)
        pixels = inp.read_image("float")
    finally:
        inp.close()
    if pixels is None:
        raise OSError(f"{path}: cannot read pixels")
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    channels = pixels.shape[2]
    if channels < 3:                   # grey, or grey + alpha
        pixels = np.repeat(pixels[:, :, :1], 3, axis=2)
    rgb = np.ascontiguousarray(pixels[:, :, :3], np.float32)
    if space == "srgb" or (space == "auto" and not is_float):
        rgb = srgb_to_linear(rgb)
    return rgb


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


def linear_to_srgb(values: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) for linear values, clipped to [0, 1]."""
    v = np.clip(np.asarray(values, np.float32), 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


def write_texture(path: str, pixels: np.ndarray):
    """An 8-bit sRGB-encoded image file (PNG by extension) from (H, W, 3)
    linear values in [0, 1], as read_texture decodes it."""
    _write_8bit(path, (linear_to_srgb(pixels) * 255 + 0.5).astype(np.uint8))


def exr_to_png(exr_path: str, png_path: str):
    """Tone-map a frame for previews: RGB over its background, clipped, sRGB encoded."""
    names, pixels, _ = read_exr(exr_path)
    srgb = linear_to_srgb(pixels[:, :, [names.index(c) for c in "RGB"]])
    _write_8bit(png_path, (srgb * 255 + 0.5).astype(np.uint8))
