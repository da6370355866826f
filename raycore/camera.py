"""Pinhole camera rays exactly as ../shared/SPEC.md section 3 fixes them."""
import numpy as np

from ._jit import kernel


def camera_basis(eye, look_at, up, fov_deg, width, height):
    """Pack the camera as a (14,) float32 array for the kernels:
    eye(3), forward(3), right(3), up'(3), h = tan(fov/2), aspect = W/H.
    Computed in float64 and rounded once."""
    eye = np.asarray(eye, np.float64)
    f = np.asarray(look_at, np.float64) - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, np.asarray(up, np.float64))
    norm_r = np.linalg.norm(r)
    if norm_r == 0.0:
        raise ValueError("camera 'up' is parallel to the viewing direction")
    r /= norm_r
    u = np.cross(r, f)
    h = np.tan(np.radians(fov_deg) / 2.0)
    return np.concatenate([eye, f, r, u, [h, width / height]]).astype(np.float32)


@kernel
def primary_dir(cam, x, y, jx, jy, width, height):
    """Unit direction through pixel (x, y) at sub-pixel offset (jx, jy) in [0,1)
    (0.5, 0.5 = pixel centre); y counts from the top."""
    h = cam[12]
    u = (2.0 * (x + jx) / width - 1.0) * h * cam[13]
    v = (1.0 - 2.0 * (y + jy) / height) * h
    dx = cam[3] + u * cam[6] + v * cam[9]
    dy = cam[4] + u * cam[7] + v * cam[10]
    dz = cam[5] + u * cam[8] + v * cam[11]
    inv = 1.0 / np.sqrt(dx * dx + dy * dy + dz * dz)
    return np.float32(dx * inv), np.float32(dy * inv), np.float32(dz * inv)
