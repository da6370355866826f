"""Render configuration, the numerical tolerances and the shared constants,
in one documented place (as trimesh.constants.tol): every margin the
kernels use is here with the reason for its size."""
from dataclasses import dataclass

import numpy as np

# Packet sizes ------------------------------------------------------------
# N for the grid's NxN camera packets; the scene schema, the command line and
# the kernels take exactly these (sub-packets are 8x8 or the whole packet)
PACKET_SIZES = (4, 8, 16, 32)

# Block sizes -------------------------------------------------------------
# The gather's pixel blocks (shading/surface.py, the sweep, the BVH's shadow
# packets made from them): the largest camera packet.
GATHER_BLOCK = 32
# Blocks whose runs on one triangle average RUN_BLOCK samples fill their runs
# of LONG_RUN or more with the triangle's data read once (surface.fill_block).
RUN_BLOCK = 12
LONG_RUN = 8

# Tolerances --------------------------------------------------------------
# Triangle AABBs and traversal ranges are widened by this fraction of the grid
# extent so that rounding in `floor((x - min) / cell)` can never drop a cell
# that a triangle touches (a triangle lying exactly on a cell boundary is
# inserted on both sides, and a frustum touching the boundary visits both).
EPS_GRID_REL = 1e-5
# Frustum culling planes are loosened by this fraction of the grid extent:
# culling may keep a triangle it could drop, never drop one it must keep.
EPS_CULL_REL = 1e-5
# Shadow ray origins are pushed off the surface along the geometric normal by
# EPS_OFFSET_ULPS float32 ulps (2^-24) of (largest |coordinate| of the hit
# triangle and lifted point + |light position| + ray length): the error of
# the hit point grows with the vertices' magnitude (pbrt-v4 bounds it by
# gamma(7) of sum |b_i v_i|), and the error of the distance at which a ray
# from the light meets the receiving plane with the magnitudes of light,
# vertices and ray length. tests/raycore/test_shadow_acne.py shows acne on ground
# planes of half-size 1e3 and 1e5 at 0 and 1 ulp, none from 2 on; 8 doubles
# the margin of pbrt's bound, and stays below what a float32 scene resolves.
EPS_OFFSET_ULPS = 8.0
# A shadow ray to a point light is traced from the light and stops short of
# it by this fraction of its length (t_min), so that a light placed on a
# surface does not shadow itself; far below any feature a float32 scene has.
SHADOW_T_MIN_FRACTION = np.float32(1e-6)
# kd-tree single rays: a split plane met within this fraction of the node's
# [t0, t1] range of its ends visits both children (rounding in (split - o) / d
# must not skip the child a ray grazes).
EPS_KD_SPLIT_REL = np.float32(1e-6)
# kd-tree root box: widened by this fraction of its largest |coordinate| so
# that triangles lying on the box faces are inside it after rounding.
EPS_KD_BOX_REL = np.float32(1e-6)


# Structures -------------------------------------------------------------
ACCELS = ("grid", "kdtree", "bvh")
# shadow rays go through the BVH unless a scene or the command line says
# otherwise: measured faster than the grid's on every built-in scene, and the
# kd-tree's single rays are slower still (docs/performance.md, the shadow pass)
SHADOW_ACCEL = "bvh"


# an error budget (render.max_error) with spp 1 lets a pixel take up to this
# many samples (its rounds end at 7, 15, 31, 63): a pixel still above the
# budget after 63 stratified samples holds a sub-pixel feature that more
# samples resolve only slowly (docs/performance.md, error against run time)
ADAPTIVE_SPP_CAP = 64


@dataclass(frozen=True)
class RenderConfig:
    width: int = 512               # image width in pixels
    height: int = 512              # image height in pixels
    packet: int = 32               # N for NxN primary-ray frustum packets (4, 8, 16, 32); 32 measured fastest
    threads: int = 0               # 0 = all cores
    spp: int = 1                   # samples per pixel (1 = exact pixel-centre ray)
    shadows: bool = True           # cast shadow rays to every light
    accel: str = "grid"            # acceleration structure of camera rays (and of every ray by default)
    accel_choice: str = ""         # why: what render.accel: auto measured and chose ("" when named)
    shadow_accel: str = ""         # structure of shadow rays; "" = SHADOW_ACCEL (measured fastest)
    grid_density: float = 0.25     # lambda: grid cells ~= lambda * triangles (0.25 measured best)
    background: tuple = (0.0, 0.0, 0.0)
    ambient: float = 0.03          # constant ambient term so shadowed areas are not pure black
    aovs: tuple = ()               # extra EXR channels: "N", "P", "id"
    grid_cull: bool = True         # grid: frustum culling and mailboxes (off only to measure them)
    light_probes: int = 0          # area lights: trace this many emitters first, the rest only in penumbrae (0 = all)
    max_error: float = 0.0         # error budget per pixel (linear RGBA); > 0: adaptive samples, spp the cap
    shutter: float = 0.0           # motion blur: the shutter is open this many frame intervals (0 = off)
    shutter_position: str = "center"   # where the frame time lies in the shutter: center | start | end
    aperture_radius: float = 0.0   # thin lens radius in scene units (0 = pinhole)
    focus_distance: float = 0.0    # distance of the sharp plane along the view axis (0 = eye to look_at)

    @property
    def shadow_structure(self) -> str:
        """The structure the shadow rays go through: shadow_accel, else SHADOW_ACCEL."""
        return self.shadow_accel or SHADOW_ACCEL
