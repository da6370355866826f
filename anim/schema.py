"""anim.yaml version 1 (../shared/SPEC.md section 2), validated by pydantic.

Unknown keys are errors (`extra="forbid"`): a typo must not pass silently;
so are inf and NaN anywhere (`allow_inf_nan=False`), a camera given both
fixed values and keys, a zero light direction and an output path that is
not one `.exr` name with at most one run of '#'.
Extensions beyond the spec's example (all optional, backward compatible):
`render.ambient`, `render.grid_density`, `render.motion_blur`,
`camera.aperture_radius` and `camera.focus_distance`, lights of `type: directional`,
more interpolation methods (anim/interpolate.py), rotation tracks with
`slerp`/`spline`, `skeleton:` (joints + skinning weights) on a mesh object,
glTF files (`.gltf`/`.glb`) and FBX files as `mesh:` with `animation:`, USD stages as
`mesh:` with `prim:`.
"""
import json
import re
from typing import Annotated, Dict, List, Literal, Optional, Tuple, Union

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from raycore.config import PACKET_SIZES

from anim.io.usd import USD_SUFFIXES

# coordinates and colours stay inside float32 with room for arithmetic (anim/tracks.py)
Coord = Annotated[float, Field(ge=-1e37, le=1e37)]
Vec3 = Tuple[Coord, Coord, Coord]
# colours are linear RGB: no negative light or reflectance (they gave negative pixels)
Channel = Annotated[float, Field(ge=0, le=1e37)]
Colour = Tuple[Channel, Channel, Channel]
Interp = Literal["linear", "catmull-rom", "centripetal", "cubic", "natural", "clamped",
                 "pchip", "akima", "makima"]
TrackInterp = Literal["linear", "catmull-rom", "centripetal", "cubic", "natural", "clamped",
                      "pchip", "akima", "makima", "slerp", "spline"]


MAX_FRAMES = 10_000_000


class Strict(BaseModel):
    """No unknown keys, no infinities, and no coercion: `samples: true`,
    `samples: "16"` and `shadows: 1` are errors, not 1, 16 and true (strict
    mode; scene data is validated as JSON, where a list may fill a tuple)."""
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


class Frames(Strict):
    start: int = 0
    end: int = 0
    fps: Annotated[float, Field(gt=0)] = 24.0

    @model_validator(mode="after")
    def _order(self):
        if self.end < self.start:
            raise ValueError(f"end ({self.end}) is before start ({self.start})")
        if self.end - self.start >= MAX_FRAMES:
            raise ValueError(f"{self.end - self.start + 1:,} frames; at most {MAX_FRAMES:,} (4.8 days at 24 fps)")
        return self


class Output(Strict):
    path: str = "out/frame_####.exr"
    resolution: Tuple[Annotated[int, Field(gt=0, le=16384)], Annotated[int, Field(gt=0, le=16384)]] = (512, 512)
    aovs: List[Literal["N", "P", "id"]] = []
    # EXR codec (raycore/images/image_io.COMPRESSIONS); zip is lossless and measured fastest
    compression: Literal["none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a", "dwaa",
                         "dwab", "zstd", "htj2k256", "htj2k32"] = "zip"

    @model_validator(mode="after")
    def _exr_pattern(self):
        if not self.path.lower().endswith(".exr"):
            raise ValueError(f"path {self.path!r}: frames are OpenEXR files, the name must end in .exr")
        if len(re.findall(r"#+", self.path)) > 1:
            raise ValueError(f"path {self.path!r}: only one run of '#' (the frame number) is allowed")
        return self


class CameraKey(Strict):
    t: float
    eye: Vec3
    look_at: Vec3
    up: Vec3 = (0.0, 1.0, 0.0)
    fov: Annotated[float, Field(gt=0, lt=180)] = 40.0


class Camera(Strict):
    eye: Optional[Vec3] = None
    look_at: Optional[Vec3] = None
    up: Vec3 = (0.0, 1.0, 0.0)
    fov: Annotated[float, Field(gt=0, lt=180)] = 40.0
    keys: Optional[List[CameraKey]] = None
    interpolation: Interp = "catmull-rom"
    # thin lens (depth of field): radius in scene units, 0 = pinhole; the sharp
    # plane's distance along the view axis, None = the eye's distance to look_at
    aperture_radius: Annotated[float, Field(ge=0, le=1e37)] = 0.0
    focus_distance: Optional[Annotated[float, Field(gt=0, le=1e37)]] = None

    @model_validator(mode="after")
    def _static_or_keyed(self):
        if self.keys is None and (self.eye is None or self.look_at is None):
            raise ValueError("needs either eye and look_at, or keys")
        if self.keys is not None and len(self.keys) == 0:
            raise ValueError("keys is empty")
        fixed = sorted(self.model_fields_set & {"eye", "look_at", "up", "fov"})
        if self.keys is not None and fixed:
            raise ValueError(f"has both keys and {', '.join(fixed)}: with keys, every key carries "
                             "its own eye, look_at, up and fov; remove the fixed ones")
        return self


class MotionBlur(Strict):
    # frame intervals the shutter is open (0 = off; 0.5 = the film "180 degree" shutter)
    shutter: Annotated[float, Field(ge=0, le=1000)] = 0.0
    # where the frame's time lies: the middle of the shutter, its opening or its closing
    position: Literal["center", "start", "end"] = "center"


class Render(Strict):
    # structure of the camera rays; auto = chosen per scene and image size
    # (anim/render/settings.auto_accel)
    accel: Literal["auto", "grid", "kdtree", "bvh"] = "auto"
    # structure of the shadow rays; None = the measured fastest (raycore.config.SHADOW_ACCEL)
    shadow_accel: Optional[Literal["grid", "kdtree", "bvh"]] = None
    packet: int = 32           # one of raycore.config.PACKET_SIZES
    shadows: bool = True
    spp: Annotated[int, Field(ge=1, le=1024)] = 1
    background: Colour = (0.0, 0.0, 0.0)
    ambient: Annotated[float, Field(ge=0)] = 0.03
    grid_density: Annotated[float, Field(gt=0, le=64)] = 0.25
    # area lights: trace this many emitters for every point first, and the
    # rest only where they disagree (the penumbra); 0 = every emitter everywhere
    light_probes: Annotated[int, Field(ge=0, le=4096)] = 0
    # error budget per pixel (linear RGBA units): start at 1 spp, give more
    # samples (up to spp, or 64 when spp is 1) only where the estimated error
    # is above it; 0 = off (raycore/adaptive.py)
    max_error: Annotated[float, Field(ge=0, le=1)] = 0.0
    motion_blur: MotionBlur = MotionBlur()
    # objects with `instances:`: copied into the frame's triangles (flatten),
    # or traced as a prototype's tree per instance under a top level
    # (two_level, raycore/instancing); auto = as measured fastest
    # (anim.instances.two_level)
    instancing: Literal["auto", "flatten", "two_level"] = "auto"

    @field_validator("packet")
    @classmethod
    def _packet(cls, v):
        if v not in PACKET_SIZES:
            raise ValueError(f"packet {v}: one of {', '.join(map(str, PACKET_SIZES))}")
        return v


class Light(Strict):
    """point: at `position`; directional: travelling along `direction`;
    area: a rectangle (`corner`, `edge_u`, `edge_v`) or a sphere (`center`,
    `radius`) of `samples` point emitters sharing `intensity`
    (anim/area_lights.py): soft shadows, and a point light in the limit of
    zero size. A rectangle's emitters radiate to both sides, the same every
    way (`sides: 2`), or, with `sides: 1`, only to the side edge_u x edge_v
    points to, with a Lambertian (cosine) falloff, as a USD RectLight does."""
    type: Literal["point", "directional", "area"] = "point"
    position: Optional[Vec3] = None
    direction: Optional[Vec3] = None
    corner: Optional[Vec3] = None
    edge_u: Optional[Vec3] = None
    edge_v: Optional[Vec3] = None
    center: Optional[Vec3] = None
    radius: Optional[Annotated[float, Field(ge=0, le=1e37)]] = None
    samples: Annotated[int, Field(ge=1, le=4096)] = 16
    sides: Literal[1, 2] = 2
    color: Colour = (1.0, 1.0, 1.0)
    intensity: Annotated[float, Field(ge=0)] = 1.0

    @model_validator(mode="after")
    def _placed(self):
        given = {k for k in ("position", "direction", "corner", "edge_u", "edge_v", "center", "radius")
                 if getattr(self, k) is not None}
        needs = {"point": [{"position"}], "directional": [{"direction"}],
                 "area": [{"corner", "edge_u", "edge_v"}, {"center", "radius"}]}[self.type]
        if given not in needs:
            shapes = " or ".join(", ".join(sorted(n)) for n in needs)
            raise ValueError(f"a{'n' if self.type == 'area' else ''} {self.type} light takes {shapes}"
                             + (f"; got {', '.join(sorted(given)) or 'none'}" if given else ""))
        if self.type == "directional" and not any(self.direction):
            raise ValueError("direction [0, 0, 0] points nowhere")
        if "samples" in self.model_fields_set and self.type != "area":
            raise ValueError("samples is for area lights")
        if self.sides == 1 and self.corner is None:
            raise ValueError("sides: 1 is for rectangle area lights (corner, edge_u, edge_v)")
        return self


class Material(Strict):
    diffuse: Colour = (0.8, 0.8, 0.8)
    specular: Annotated[float, Field(ge=0)] = 0.0
    shininess: Annotated[float, Field(ge=0)] = 32.0
    texture: Optional[str] = None
    # how the texture's values are encoded: auto = sRGB for integer formats
    # (8/16-bit PNG, JPEG: colour by convention), linear for float ones (EXR, HDR);
    # linear for data textures stored in 8 bits
    texture_space: Literal["auto", "srgb", "linear"] = "auto"


class Track(Strict):
    """Rows [t, values...]. Rotation tracks: slerp (or linear) / spline."""
    interpolation: TrackInterp = "linear"
    keys: List[List[float]]


class AngleTrack(Strict):
    """Joint angles in degrees, rows [t, a, b, c], about the axes of `order`
    (scipy's Euler convention: lower case extrinsic, upper case intrinsic)."""
    order: Annotated[str, Field(pattern=r"^([xyz]{3}|[XYZ]{3})$")] = "xyz"
    interpolation: Interp = "linear"
    keys: List[List[float]]


class Joint(Strict):
    """A joint rotates its vertices about its `origin` (bind-pose position, in
    mesh coordinates) and carries its children along."""
    name: str
    parent: Optional[str] = None
    origin: Vec3 = (0.0, 0.0, 0.0)
    rotation: Optional[Track] = None
    angles: Optional[AngleTrack] = None
    translation: Optional[Track] = None

    @model_validator(mode="after")
    def _one_rotation(self):
        if self.rotation is not None and self.angles is not None:
            raise ValueError("give 'rotation' (quaternions) or 'angles', not both")
        return self


class Skeleton(Strict):
    """Linear blend skinning. `weights`: an .npz file with `joints` (n_v, k)
    joint indices (the order of `joints` below) and `weights` (n_v, k)."""
    weights: str
    joints: Annotated[List[Joint], Field(min_length=1)]


class Transform(Strict):
    translation: Optional[Track] = None
    rotation: Optional[Track] = None
    scale: Optional[Track] = None


class Keyframe(Strict):
    t: float
    mesh: str


class InstanceKey(Strict):
    """One key of an instance table: a row per instance."""
    t: float
    translation: List[Vec3]
    rotation: Optional[List[Tuple[float, float, float, float]]] = None     # w, x, y, z
    scale: Optional[List[Union[Coord, Vec3]]] = None
    visible: Optional[List[bool]] = None


class Instances(Strict):
    """Copies of the object, each placed by its own TRS over time (anim/instances.py):
    `keys` inline, or `file`: an .npz of arrays t (k,), translation (k, n, 3) and
    optionally rotation (k, n, 4) w x y z, scale (k, n, 3) or (k, n), visible (k, n)."""
    keys: Optional[Annotated[List[InstanceKey], Field(min_length=1)]] = None
    file: Optional[str] = None
    interpolation: Interp = "linear"

    @model_validator(mode="after")
    def _one_source(self):
        if (self.keys is None) == (self.file is None):
            raise ValueError("needs exactly one of 'keys' or 'file'")
        return self


class Object(Strict):
    name: str
    material: Optional[str] = None
    mesh: Optional[str] = None
    transform: Optional[Transform] = None
    keyframes: Optional[List[Keyframe]] = None
    skeleton: Optional[Skeleton] = None
    animation: Optional[Union[int, str, Annotated[List[Union[int, str]], Field(min_length=1)]]] = None
    prim: Optional[str] = None
    instances: Optional[Instances] = None
    interpolation: Interp = "linear"
    extrapolate: Literal["clamp", "loop"] = "clamp"

    @model_validator(mode="after")
    def _kind(self):
        if (self.mesh is None) == (self.keyframes is None):
            raise ValueError("needs exactly one of 'mesh' or 'keyframes'")
        if self.keyframes is not None and (self.transform is not None or self.skeleton is not None):
            raise ValueError("'transform' and 'skeleton' go with 'mesh', not with 'keyframes'")
        is_gltf = self.mesh is not None and self.mesh.lower().endswith((".gltf", ".glb"))
        is_fbx = self.mesh is not None and self.mesh.lower().endswith(".fbx")
        if self.animation is not None and not (is_gltf or is_fbx):
            raise ValueError("'animation' selects an animation of a .gltf/.glb mesh or a take of an .fbx mesh")
        if (is_gltf or is_fbx) and self.skeleton is not None:
            raise ValueError("a glTF or FBX file brings its own skins; 'skeleton' is for other meshes")
        is_usd = self.mesh is not None and self.mesh.lower().endswith(USD_SUFFIXES)
        if self.prim is not None and not is_usd:
            raise ValueError("'prim' selects a prim of a USD stage (.usd, .usda, .usdc, .usdz)")
        if is_usd and self.skeleton is not None:
            raise ValueError("a USD stage brings its own skeletons; 'skeleton' is for other meshes")
        if self.keyframes is not None and len(self.keyframes) == 0:
            raise ValueError("keyframes is empty")
        return self


class SceneFile(Strict):
    version: Literal[1]
    frames: Frames = Frames()
    output: Output = Output()
    camera: Camera
    render: Render = Render()
    lights: List[Light] = []
    materials: Dict[str, Material] = {}
    objects: List[Object]


def parse_scene(data: dict) -> "SceneFile":
    """A scene file's parsed YAML, validated strictly (Strict): through JSON,
    so that YAML lists fill tuples as in JSON. A value JSON cannot hold (a
    date, a set) is a TypeError naming its type."""
    def refuse(value):
        raise TypeError(f"a value of type {type(value).__name__} ({value!r}) is not allowed here")
    try:
        text = json.dumps(data, default=refuse)
    except ValueError:                    # json's "Circular reference detected"
        raise TypeError("a value contains itself (a YAML anchor used inside its own value)") from None
    return SceneFile.model_validate_json(text)
