"""Texture lookup: texel centres exact, bilinear between them, wrap-around."""
import numpy as np

from raycore.surface import sample_texture


def texture(w=4, h=3):
    texels = np.arange(w * h * 3, dtype=np.float32).reshape(h, w, 3)
    return texels, texels.reshape(-1), np.array([[0, w, h]], np.int64)


def lookup(u, v, w=4, h=3):
    _, data, info = texture(w, h)
    return np.array(sample_texture(data, info, 0, np.float32(u), np.float32(v)))


def test_texel_centres_are_exact_and_v0_is_the_bottom_row():
    img, _, _ = texture()
    for row in range(3):
        for col in range(4):
            u = (col + 0.5) / 4
            v = 1 - (row + 0.5) / 3
            np.testing.assert_allclose(lookup(u, v), img[row, col], atol=1e-4)


def test_bilinear_midpoint_and_wrap_around():
    img, _, _ = texture()
    mid = lookup(1.0 / 4, 1 - 0.5 / 3)                     # between columns 0 and 1 of row 0
    np.testing.assert_allclose(mid, (img[0, 0] + img[0, 1]) / 2, atol=1e-4)
    wrap = lookup(0.0, 1 - 0.5 / 3)                         # between column 3 and (wrapped) 0
    np.testing.assert_allclose(wrap, (img[0, 3] + img[0, 0]) / 2, atol=1e-4)
    np.testing.assert_allclose(lookup(1.3, 0.4), lookup(0.3, 0.4), atol=1e-4)
    np.testing.assert_allclose(lookup(-0.7, 0.4), lookup(0.3, 0.4), atol=1e-4)
