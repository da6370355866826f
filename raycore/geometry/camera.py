"""Camera rays exactly as ../shared/SPEC.md section 3 fixes them, and the
thin lens of depth of field as one pinhole per lens position."""
import numpy as np

from raycore.jit.presets import helper


def camera_basis(eye, look_at, up, fov_deg, width, height, dtype=np.float32):
    """Pack the camera as a (19,) array for the kernels (float32; float64
    for references): eye(3), forward(3), right(3), up'(3), h*aspect, h,
    2 h aspect / W, 2 h / H with h = tan(fov/2), aspect = W/H, and the view
    axis(3) that Z is measured along (the forward of a pinhole; thin_lens
    shears the forward and keeps this). Computed in float64, rounded once."""
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
    a = width / height
    return np.concatenate([eye, f, r, u, [h * a, h, 2 * h * a / width, 2 * h / height], f]).astype(dtype)


def thin_lens(cam, lens_x, lens_y, aperture_radius, focus_distance):
    """The camera of one lens position: a ray from the lens point
    o = eye + A (x right + y up') toward the point that the pinhole ray
    through the same pixel meets on the focus plane (distance F along the
    view axis), eye + F (forward + u right + v up'). Its direction,
    divided by F, is forward - (A/F)(x right + y up') + u right + v up':
    the pinhole formula with the eye moved to o and the forward sheared, so
    every kernel keeps working, and a pass's camera rays still share one
    origin and stay frustum packets. (x, y) is a point of the unit disc."""
    out = np.array(cam, np.float64)
    ax, ay = aperture_radius * lens_x, aperture_radius * lens_y
    out[0:3] += ax * out[6:9] + ay * out[9:12]
    out[3:6] -= (ax * out[6:9] + ay * out[9:12]) / focus_distance
    return out.astype(np.asarray(cam).dtype)


def pixel_centre_rays(cam, width, height):
    """Origins (n, 3) and unit directions (n, 3), float64, of the pixel-centre
    rays of basis `cam`, row-major from the top: numpy, for references and
    other ray casters (the kernels compute theirs with primary_dir)."""
    cam = np.asarray(cam, np.float64)
    x = (np.arange(width) + 0.5) * cam[14] - cam[12]
    y = cam[13] - (np.arange(height) + 0.5) * cam[15]
    u, v = np.meshgrid(x, y)
    d = cam[3:6] + u[..., None] * cam[6:9] + v[..., None] * cam[9:12]
    d = (d / np.linalg.norm(d, axis=-1, keepdims=True)).reshape(-1, 3)
    return np.broadcast_to(cam[:3], d.shape).copy(), d


@helper
def primary_dir(cam, x, y, jx, jy):
    """Unit direction through pixel (x, y) at sub-pixel offset (jx, jy) in [0,1)
    (0.5, 0.5 = pixel centre); y counts from the top. SPEC's
    u = (2 (x + jx) / W - 1) h aspect, v = (1 - 2 (y + jy) / H) h, in float32."""
    dx, dy, dz = primary_dir_raw(cam, x, y, jx, jy)
    inv = np.float32(1.0) / np.sqrt(dx * dx + dy * dy + dz * dz)
    return dx * inv, dy * inv, dz * inv


@helper
def primary_dir_raw(cam, x, y, jx, jy):
    """primary_dir before normalisation: forward + u right + v up', affine in
    the pixel position (so a packet's extremes are at its corner rays)."""
    u = (np.float32(x) + jx) * cam[14] - cam[12]
    v = cam[13] - (np.float32(y) + jy) * cam[15]
    return (cam[3] + u * cam[6] + v * cam[9], cam[4] + u * cam[7] + v * cam[10],
            cam[5] + u * cam[8] + v * cam[11])
