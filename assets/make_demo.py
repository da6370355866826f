"""Writes the demo animation in anim/builtin/demo/: a tube that bends (vertex
keyframes), a ball that bounces and spins (TRS tracks), a checkered floor
(texture), one point light. Deterministic; re-run to regenerate."""
from pathlib import Path

import numpy as np

from anim.builtin.shapes import icosphere

HERE = Path(__file__).resolve().parent.parent / "anim" / "builtin" / "demo"


def write_obj(path, vertices, faces, uvs=None):
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    if uvs is not None:
        lines += [f"vt {u:.6f} {v:.6f}" for u, v in uvs]
        lines += [f"f {a+1}/{a+1} {b+1}/{b+1} {c+1}/{c+1}" for a, b, c in faces]
    else:
        lines += [f"f {a+1} {b+1} {c+1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")


def tube(bend, n_around=48, n_along=64, radius=0.18, length=1.6):
    """A capped-free tube along +y whose axis bends in the x-y plane by `bend` radians."""
    s = np.linspace(0.0, 1.0, n_along)
    a = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False)
    if abs(bend) < 1e-9:
        cx, cy = np.zeros_like(s), s * length
        tx, ty = np.zeros_like(s), np.ones_like(s)
    else:
        r_bend = length / bend
        ang = s * bend
        cx, cy = r_bend * (1 - np.cos(ang)), r_bend * np.sin(ang)
        tx, ty = np.sin(ang), np.cos(ang)
    nx, ny = ty, -tx                       # in-plane normal of the axis
    rad = radius * (1.0 - 0.3 * s)
    v = np.empty((n_along, n_around, 3))
    v[..., 0] = cx[:, None] + rad[:, None] * np.cos(a)[None, :] * nx[:, None]
    v[..., 1] = cy[:, None] + rad[:, None] * np.cos(a)[None, :] * ny[:, None]
    v[..., 2] = rad[:, None] * np.sin(a)[None, :]
    i, j = np.meshgrid(np.arange(n_along - 1), np.arange(n_around), indexing="ij")
    p00 = i * n_around + j
    p01 = i * n_around + (j + 1) % n_around
    p10 = (i + 1) * n_around + j
    p11 = (i + 1) * n_around + (j + 1) % n_around
    faces = np.concatenate([np.stack([p00, p10, p11], -1).reshape(-1, 3),
                            np.stack([p00, p11, p01], -1).reshape(-1, 3)])
    return v.reshape(-1, 3), faces


def checker(path, n=256, squares=8):
    import OpenImageIO as oiio
    y, x = np.mgrid[0:n, 0:n]
    c = ((x * squares // n + y * squares // n) % 2).astype(np.float32)
    img = np.stack([0.25 + 0.6 * c, 0.25 + 0.55 * c, 0.3 + 0.4 * c], -1).astype(np.float32)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(n, n, 3, "uint8"))
    out.write_image((np.clip(img, 0, 1) * 255).astype(np.uint8))
    out.close()


def main():
    HERE.mkdir(parents=True, exist_ok=True)
    for k, bend in enumerate([0.0, 1.2, 0.0, -1.2, 0.0]):
        v, f = tube(bend)
        write_obj(HERE / f"tube_{k:03d}.obj", v, f)
    v, f = icosphere(3, 0.35)
    write_obj(HERE / "ball.obj", v, f)
    floor = np.array([[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], float)
    uv = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], float)
    write_obj(HERE / "floor.obj", floor, np.array([[0, 2, 1], [0, 3, 2]]), uv)
    checker(HERE / "checker.png")


if __name__ == "__main__":
    main()
