"""How the rays of a packet are laid out: sub-packets of SxS rays inside an
NxN packet, the per-thread scratch a packet is traced in, and the
packet-major hit arrays of the camera pass (and their row-major view).

Rays are SoA float32 arrays shaped (row, sub-packet j, ray r); the row
numbers are grid/cgt.py's (rays OX..TMAX, work OU..DV, sub-packet bounds UMIN..WMAX).
"""
import numpy as np
from numba import prange

from raycore.jit.presets import kernel, parallel_kernel
from raycore.grid.cgt import MAILBOX_SIZE, N_SUB_ROWS, N_WORK


@kernel
def sub_corner(px, py, j, packet, sub_size):
    """Top-left pixel of sub-packet j of the packet whose corner is (px, py).
    Ray r = ly * sub_size + lx of that sub-packet is pixel (x0 + lx, y0 + ly)."""
    n_sx = packet // sub_size
    return px + (j % n_sx) * sub_size, py + (j // n_sx) * sub_size


@kernel
def ray_offsets(sub_size):
    """(lx, ly) of ray r in a sub-packet, as tables so that per-ray loops run
    over r alone (no division, vectorizable)."""
    ss = sub_size * sub_size
    lx = np.empty(ss, np.int64)
    ly = np.empty(ss, np.int64)
    for r in range(ss):
        lx[r] = r % sub_size
        ly[r] = r // sub_size
    return lx, ly


@kernel
def packet_scratch(packet, sub_size):
    """One thread's packet scratch: rays (8, n_sub, ss), work (N_WORK, n_sub,
    ss), hit t/b1/b2/prim (n_sub, ss), sub bounds (N_SUB_ROWS, n_sub + 1), sub-packet
    live and done counts, mailbox."""
    ss = sub_size * sub_size
    n_sub = packet * packet // ss
    return (np.empty((8, n_sub, ss), np.float32), np.empty((N_WORK, n_sub, ss), np.float32),
            np.empty((n_sub, ss), np.float32), np.zeros((n_sub, ss), np.float32),
            np.zeros((n_sub, ss), np.float32), np.empty((n_sub, ss), np.int32),
            np.empty((N_SUB_ROWS, n_sub + 1), np.float32), np.empty(n_sub, np.int32),
            np.empty(n_sub, np.int32), np.empty(n_sub, np.bool_), np.empty(MAILBOX_SIZE, np.int32))


def swizzle_offsets(width, height, packet, sub_size):
    """Row and column terms of the packet-major index of pixel (x, y):
    flat index into sw_*.reshape(-1) = row_off[y] + col_off[x]."""
    n_sx = packet // sub_size
    ss = sub_size * sub_size
    n_sub = n_sx * n_sx
    packets_x = -(-width // packet)
    y = np.arange(height)
    x = np.arange(width)
    row_off = ((y // packet) * packets_x * n_sub * ss + ((y % packet) // sub_size) * n_sx * ss
               + (y % sub_size) * sub_size)
    col_off = (x // packet) * n_sub * ss + ((x % packet) // sub_size) * ss + x % sub_size
    return row_off.astype(np.int64), col_off.astype(np.int64)


@parallel_kernel
def unswizzle(sw_t, sw_prim, sw_b1, sw_b2, row_off, col_off, out_t, out_prim, out_b1, out_b2):
    """Packet-major hits -> row-major (H*W,) images (a gather per pixel)."""
    width = col_off.shape[0]
    for y in prange(row_off.shape[0]):
        base = row_off[y]
        p0 = y * width
        for x in range(width):
            k = base + col_off[x]
            out_t[p0 + x] = sw_t[k]
            out_prim[p0 + x] = sw_prim[k]
            out_b1[p0 + x] = sw_b1[k]
            out_b2[p0 + x] = sw_b2[k]
