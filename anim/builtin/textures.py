"""Procedural textures for the built-in scenes: (H, W, 3) float arrays in
[0, 1], written to PNG by raycore.images.image_io.write_texture (OpenImageIO)."""
import numpy as np


def checker(n=256, squares=8, dark=(0.25, 0.25, 0.3), light=(0.8, 0.78, 0.7)):
    y, x = np.mgrid[0:n, 0:n]
    c = ((x * squares // n + y * squares // n) % 2).astype(float)[..., None]
    return np.asarray(dark) * (1 - c) + np.asarray(light) * c


def value_noise(n, cells, seed):
    """Smooth tileable noise in [0, 1]: a bicubic upsampling of random values."""
    rng = np.random.default_rng(seed)
    grid = rng.random((cells, cells))
    u = np.arange(n) * cells / n
    i0 = np.floor(u).astype(int)
    f = u - i0
    f = f * f * (3 - 2 * f)
    a = grid[i0 % cells][:, i0 % cells]
    b = grid[(i0 + 1) % cells][:, i0 % cells]
    c = grid[i0 % cells][:, (i0 + 1) % cells]
    d = grid[(i0 + 1) % cells][:, (i0 + 1) % cells]
    fy, fx = f[:, None], f[None, :]
    return (a * (1 - fy) + b * fy) * (1 - fx) + (c * (1 - fy) + d * fy) * fx


def grass(n=256, seed=7):
    """Mottled green ground."""
    noise = 0.6 * value_noise(n, 8, seed) + 0.4 * value_noise(n, 32, seed + 1)
    return np.stack([0.18 + 0.15 * noise, 0.35 + 0.3 * noise, 0.12 + 0.1 * noise], -1)


def stripes(n=128, count=6, a=(0.9, 0.2, 0.15), b=(0.95, 0.9, 0.85)):
    """Horizontal stripes (the toy ball)."""
    y = np.arange(n)[:, None] * np.ones((1, n))
    c = ((y * count // n) % 2)[..., None]
    return np.asarray(a) * (1 - c) + np.asarray(b) * c
