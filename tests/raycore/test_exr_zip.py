"""The zip EXR encoder (raycore/images/exr_zip.py) against OpenEXR's own readers:
every file it writes decodes bit for bit through the OpenEXR bindings and
OpenImageIO, and its blocks inflate to the bytes OpenEXR's reorder and
predictor (ImfZip.cpp, written out below byte by byte) make of the raw lines."""
import struct
import zlib

import numpy as np
import OpenEXR
import OpenImageIO as oiio
import pytest

from raycore.images import exr_zip
from raycore.images.image_io import write_exr


def openexr_zip_bytes(raw: bytes) -> bytes:
    """ImfZip.cpp's compress before deflate, as the C++ does it: bytes at even
    positions to the first half, odd ones to the second, then each byte minus
    its predecessor plus 128 (mod 256)."""
    t = bytearray(len(raw))
    t1, t2 = 0, (len(raw) + 1) // 2
    for i, b in enumerate(raw):
        if i % 2 == 0:
            t[t1] = b
            t1 += 1
        else:
            t[t2] = b
            t2 += 1
    out = bytearray(t)
    for i in range(1, len(t)):
        out[i] = (t[i] - t[i - 1] + 128 + 256) % 256
    return bytes(out)


def raw_lines(channels: dict, y0: int, y1: int) -> bytes:
    """The uncompressed bytes of scanlines y0..y1-1: per line, channels by name."""
    return b"".join(channels[n][y].tobytes() for y in range(y0, y1) for n in sorted(channels))


def chunks_of(data: bytes):
    """(y, payload) of every chunk, through the offset table of a parsed header."""
    i = 8
    while data[i] != 0:
        i = data.index(b"\0", data.index(b"\0", i) + 1) + 1
        i += 4 + struct.unpack_from("<i", data, i)[0]
    i += 1
    first = struct.unpack_from("<Q", data, i)[0]
    count = (first - i) // 8
    for k in range(count):
        at = struct.unpack_from("<Q", data, i + 8 * k)[0]
        y, size = struct.unpack_from("<ii", data, at)
        yield y, data[at + 8:at + 8 + size]


def random_channels(rng, h, w):
    half = lambda: rng.normal(0, 3, (h, w)).astype(np.float16)
    ch = {"R": half(), "G": half(), "B": half(), "A": half(),
          "Z": rng.exponential(5, (h, w)).astype(np.float32), "N.X": rng.normal(size=(h, w)).astype(np.float32),
          "id": rng.integers(-1, 1000, (h, w)).astype(np.float32)}
    # the special values a frame carries: misses at +inf, NaN, signed zeros, subnormals
    ch["Z"][0, :] = np.inf
    ch["R"].flat[::7] = np.float16(np.nan)
    ch["G"].flat[::5] = np.float16(-0.0)
    ch["B"].flat[::3] = np.float16(6e-8)
    ch["N.X"].flat[::11] = np.float32(1e-45)
    return ch


def bits(a):
    return np.ascontiguousarray(a).view(np.uint8)


def read_back(path, names):
    """Each channel as OpenImageIO and as the OpenEXR bindings decode it."""
    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    px = inp.read_image("float")
    inp.close()
    by_oiio = {n: px[..., spec.channelnames.index(n)] for n in names}
    with OpenEXR.File(str(path)) as f:
        by_exr = {}
        for name, ch in f.channels().items():
            if name == "RGBA":
                by_exr.update({c: ch.pixels[..., k] for k, c in enumerate("RGBA")})
            else:
                by_exr[name] = ch.pixels
    return by_oiio, by_exr, spec


@pytest.mark.parametrize("codec", ["zip", "zips"])
@pytest.mark.parametrize("h, w", [(1, 1), (17, 33), (64, 48), (5, 1024)])
def test_frames_decode_bit_for_bit_in_both_readers(tmp_path, rng, codec, h, w):
    ch = random_channels(rng, h, w)
    path = tmp_path / "f.exr"
    path.write_bytes(b"".join(exr_zip.encode(ch, {"frustrace:frame": 7}, codec)))
    by_oiio, by_exr, spec = read_back(path, ch)
    assert spec.get_string_attribute("compression") == codec
    for name, want in ch.items():
        assert by_exr[name].dtype == want.dtype, name
        np.testing.assert_array_equal(bits(by_exr[name]), bits(want), err_msg=name)
        np.testing.assert_array_equal(bits(by_oiio[name].astype(want.dtype)), bits(want), err_msg=name)


@pytest.mark.parametrize("codec, lines", [("zip", 16), ("zips", 1)])
def test_blocks_inflate_to_openexrs_reorder_and_predictor(rng, codec, lines):
    h, w = 37, 21
    ch = random_channels(rng, h, w)
    ch["Z"][:] = 1.5                       # compressible, so that every block is deflated
    chunks = list(chunks_of(b"".join(exr_zip.encode(ch, {}, codec))))
    assert [y for y, _ in chunks] == list(range(0, h, lines))
    for y, payload in chunks:
        raw = raw_lines(ch, y, min(y + lines, h))
        if len(payload) == len(raw):
            assert payload == raw            # stored as it is
        else:
            assert zlib.decompress(payload) == openexr_zip_bytes(raw), y


def test_a_block_deflate_cannot_shrink_is_stored_raw_and_still_reads(tmp_path, rng):
    h, w = 20, 64
    ch = {"Z": rng.integers(0, 2 ** 32, (h, w), dtype=np.uint64).astype(np.uint32).view(np.float32)}
    ch["Z"][np.isnan(ch["Z"])] = 0.0                # readers may canonicalise NaN payloads
    data = b"".join(exr_zip.encode(ch, {}, "zip"))
    stored = [len(p) == len(raw_lines(ch, y, min(y + 16, h))) for y, p in chunks_of(data)]
    assert any(stored), "random bits should not deflate"
    (tmp_path / "r.exr").write_bytes(data)
    _, by_exr, _ = read_back(tmp_path / "r.exr", ch)
    np.testing.assert_array_equal(bits(by_exr["Z"]), bits(ch["Z"]))


def test_metadata_types_and_long_names(tmp_path, rng):
    ch = {"Z": np.ones((4, 4), np.float32)}
    long_name = "frustrace:" + "x" * 40
    meta = {"frustrace:frame": 12, "frustrace:time": 0.375, "Software": "frustrace test", long_name: "long"}
    data = b"".join(exr_zip.encode(ch, meta, "zip"))
    assert struct.unpack_from("<ii", data)[1] == 2 | exr_zip.LONG_NAMES
    (tmp_path / "m.exr").write_bytes(data)
    spec = oiio.ImageInput.open(str(tmp_path / "m.exr")).spec()
    assert spec.get_int_attribute("frustrace:frame") == 12
    assert spec.get_float_attribute("frustrace:time") == 0.375
    assert spec.get_string_attribute("Software") == "frustrace test"
    assert spec.get_string_attribute(long_name) == "long"
    short = b"".join(exr_zip.encode(ch, {"frustrace:frame": 1}, "zip"))
    assert struct.unpack_from("<ii", short)[1] == 2
    with pytest.raises(TypeError, match="frustrace:flag"):
        exr_zip.encode(ch, {"frustrace:flag": True}, "zip")
    with pytest.raises(ValueError, match="compression"):
        exr_zip.encode(ch, {"compression": "zip"}, "zip")


def test_write_exr_zip_matches_the_openexr_library_pixel_for_pixel(tmp_path, rng):
    """The frame write (image_io.write_exr: float32 in, half R G B A) gives
    the pixels OpenEXR's own zip writer gives (its piz codec, also lossless,
    stands in: the bindings' zip is the path this encoder replaced)."""
    h, w = 48, 40
    rgba = rng.normal(0, 2, (h, w, 4)).astype(np.float32)
    z = rng.exponential(3, (h, w)).astype(np.float32)
    write_exr(str(tmp_path / "ours.exr"), {"RGBA": rgba, "Z": z}, {"frustrace:frame": 3}, "zip")
    write_exr(str(tmp_path / "lib.exr"), {"RGBA": rgba, "Z": z}, {"frustrace:frame": 3}, "piz")
    names = ["R", "G", "B", "A", "Z"]
    ours_oiio, ours_exr, spec = read_back(tmp_path / "ours.exr", names)
    lib_oiio, lib_exr, _ = read_back(tmp_path / "lib.exr", names)
    for n in names:
        np.testing.assert_array_equal(bits(ours_exr[n]), bits(lib_exr[n]), err_msg=n)
        np.testing.assert_array_equal(ours_oiio[n], lib_oiio[n], err_msg=n)
    assert spec.get_int_attribute("frustrace:frame") == 3
    assert not list(tmp_path.glob(".*"))            # no temporary file left
