"""Per-vertex kernels of the animation stage: spline evaluation and linear
blend skinning. Parallel over vertices, float64 arithmetic (keys may sit at
1e6 with 1e-3 detail), float32 results straight into the scene's buffer."""
import numpy as np
from numba import prange

from raycore.jit.presets import parallel_arith_kernel


@parallel_arith_kernel
def horner_into(c0, c1, c2, c3, s, out):
    """out[i] = c0 + c1 s + c2 s^2 + c3 s^3 (flat float64 coefficients)."""
    for i in prange(out.shape[0]):
        out[i] = np.float32(((c3[i] * s + c2[i]) * s + c1[i]) * s + c0[i])


@parallel_arith_kernel
def skin_into(rest, joint, weight, mats, out):
    """Linear blend skinning: out[v] = sum_k weight[v,k] * mats[joint[v,k]] @ (rest[v], 1).

    rest (n, 3) f32; joint (n, k) int32; weight (n, k) f32, rows summing to 1;
    mats (J, 3, 4) f64 (joint pose times inverse bind)."""
    for v in prange(rest.shape[0]):
        x, y, z = np.float64(rest[v, 0]), np.float64(rest[v, 1]), np.float64(rest[v, 2])
        ox = oy = oz = 0.0
        for k in range(joint.shape[1]):
            w = np.float64(weight[v, k])
            if w == 0.0:
                continue
            m = mats[joint[v, k]]
            ox += w * (m[0, 0] * x + m[0, 1] * y + m[0, 2] * z + m[0, 3])
            oy += w * (m[1, 0] * x + m[1, 1] * y + m[1, 2] * z + m[1, 3])
            oz += w * (m[2, 0] * x + m[2, 1] * y + m[2, 2] * z + m[2, 3])
        out[v, 0] = np.float32(ox)
        out[v, 1] = np.float32(oy)
        out[v, 2] = np.float32(oz)


@parallel_arith_kernel
def transform_into(rest, mat, out):
    """Rigid (affine) motion: out[v] = mat @ (rest[v], 1), mat (3, 4) f64."""
    for v in prange(rest.shape[0]):
        x, y, z = np.float64(rest[v, 0]), np.float64(rest[v, 1]), np.float64(rest[v, 2])
        out[v, 0] = np.float32(mat[0, 0] * x + mat[0, 1] * y + mat[0, 2] * z + mat[0, 3])
        out[v, 1] = np.float32(mat[1, 0] * x + mat[1, 1] * y + mat[1, 2] * z + mat[1, 3])
        out[v, 2] = np.float32(mat[2, 0] * x + mat[2, 1] * y + mat[2, 2] * z + mat[2, 3])


@parallel_arith_kernel
def instances_into(proto, mats, out):
    """Copies of a prototype: out[i * m + v] = mats[i] @ (proto[v], 1) for
    proto (m, 3) f32 and mats (n, 3, 4) f64, out (n * m, 3) f32."""
    m = proto.shape[0]
    for j in prange(mats.shape[0] * m):
        i, v = j // m, j % m
        x, y, z = np.float64(proto[v, 0]), np.float64(proto[v, 1]), np.float64(proto[v, 2])
        a = mats[i]
        out[j, 0] = np.float32(a[0, 0] * x + a[0, 1] * y + a[0, 2] * z + a[0, 3])
        out[j, 1] = np.float32(a[1, 0] * x + a[1, 1] * y + a[1, 2] * z + a[1, 3])
        out[j, 2] = np.float32(a[2, 0] * x + a[2, 1] * y + a[2, 2] * z + a[2, 3])


@parallel_arith_kernel
def lerp_into(p0, p1, u, out):
    """out[i] = p0[i] + (p1[i] - p0[i]) u, in float64 (flat float32 arrays)."""
    for i in prange(out.shape[0]):
        a = np.float64(p0[i])
        out[i] = np.float32(a + (np.float64(p1[i]) - a) * u)
