"""A whole FBX file as a scene (`frustrace render shot.fbx`): its meshes as
one object playing every take (`animation: all`), its camera per frame and
its lights, with notes on what came from the file and what from
frustrace's defaults (as a whole USD stage is read, usd.scene_of_stage).

Axes and units are converted as for FBX objects (Y up, metres); cameras
and lights are read looking and shining along their -Z. Light intensities
are the file's (ufbx's `intensity`: FBX's Intensity / 100), under
frustrace's rules (a point light's irradiance is intensity / d², a
directional light's its intensity), but for files Blender wrote, whose
lights are in watts (points) and W/m² (suns) under a diffuse BRDF of
albedo / pi: there a point of P watts is P / (4 pi²) and a sun of S is S / pi,
so a diffuse surface is as bright as in Blender."""
import math
from pathlib import Path

import numpy as np

from anim.errors import SceneError
from anim.io.fbx import open_fbx, take_of

DEFAULT_WIDTH = 512


def _vec(v):
    return [float(x) for x in v]


def _frames(takes, played, fps, notes):
    """(start, end) frames covering the played takes' time ranges."""
    if not played:
        notes.append("the file has no takes: frame 0 only")
        return 0, 0
    t0, t1 = min(takes[k]["begin"] for k in played), max(takes[k]["end"] for k in played)
    start = math.ceil(t0 * fps - 1e-6)
    end = max(start, math.floor(t1 * fps + 1e-6))
    notes.append(f"frames {start}..{end} at {fps:g} fps from the takes' time range ({t0:g}..{t1:g} s)")
    return start, end


def _camera(worker, info, which, start, end, fps, path, notes):
    """(the scene's camera dict or None, its resolution or None)."""
    cams = info["cameras"]
    if which is not None:
        names = [c["name"] for c in cams]
        if which not in names:
            raise SceneError(path, "--camera", f"no camera {which!r} in the file (its cameras: "
                                               f"{', '.join(names) or 'none'})")
        index = names.index(which)
    elif cams:
        index = 0
    else:
        return None, None
    cam = cams[index]
    if not cam["perspective"]:
        raise SceneError(path, "--camera" if which else "", f"camera {cam['name']!r} is orthographic; "
                                                            "frustrace renders perspective cameras only")
    take, note = take_of(cam["drivers"], info["takes"], range(len(info["takes"])))
    if note:
        notes.append(f"camera {cam['name']!r}: {note}")
    keys = []
    for f, (m, fov) in zip(range(start, end + 1),
                           worker.call("camera", index, take, [f / fps for f in range(start, end + 1)])):
        m = np.asarray(m)
        eye, forward, up = m[:, 3], -m[:, 2] / np.linalg.norm(m[:, 2]), m[:, 1] / np.linalg.norm(m[:, 1])
        keys.append({"t": f / fps, "eye": _vec(eye), "look_at": _vec(eye + forward), "up": _vec(up),
                     "fov": min(max(fov, 1e-3), 179.0)})
    still = all({k: v for k, v in key.items() if k != "t"} == {k: v for k, v in keys[0].items() if k != "t"}
                for key in keys)
    notes.append(f"camera {cam['name']!r} (vertical field of view {keys[0]['fov']:.2f} degrees"
                 f"{', still' if still else ', animated'})")
    data = ({k: keys[0][k] for k in ("eye", "look_at", "up", "fov")} if still
            else {"keys": keys, "interpolation": "linear"})
    if cam["resolution"] and min(cam["resolution"]) >= 1:
        res = [int(round(cam["resolution"][0])), int(round(cam["resolution"][1]))]
        notes.append(f"resolution {res[0]}x{res[1]} from the camera (render --res to change it)")
    else:
        aspect = cam["aspect"] if cam["aspect"] > 0 else 1.0
        res = [DEFAULT_WIDTH, max(1, round(DEFAULT_WIDTH / aspect))]
        notes.append(f"resolution {res[0]}x{res[1]}: frustrace's default width, the camera's aspect")
    return data, res


def _lights(worker, info, t, notes):
    """frustrace light dicts from the file's lights at time t."""
    blender = info["creator"].startswith("Blender")
    if blender and info["lights"]:
        notes.append("lights in Blender's units (watts, W/m²): point P -> intensity P/(4 pi^2), sun S -> S/pi")
    takes = [take_of(light["drivers"], info["takes"], range(len(info["takes"])))[0] for light in info["lights"]]
    lights = []
    for light in worker.call("lights", takes, t) if takes else []:
        name, kind = light["name"], light["type"]
        if not light["visible"] or light["intensity"] <= 0:
            notes.append(f"light {name!r} is hidden or dark; left out")
            continue
        common = {"color": _vec(light["colour"]), "intensity": light["intensity"]}
        if blender:
            common["intensity"] /= math.pi if kind == "directional" else 4 * math.pi ** 2
        if kind == "directional":
            d = np.asarray(light["direction"])
            lights.append({"type": "directional", "direction": _vec(d / np.linalg.norm(d)), **common})
            continue
        if kind not in ("point", "spot", "area"):
            notes.append(f"light {name!r} ({kind}) is not supported; left out")
            continue
        if kind != "point":
            notes.append(f"light {name!r} ({kind}) is rendered as a point light at its position")
        if light["decay"] != "quadratic":
            notes.append(f"light {name!r} has {light['decay']} decay; frustrace's point lights fall off as 1/d²")
        lights.append({"type": "point", "position": _vec(light["position"]), **common})
    return lights


def scene_of_fbx(path, camera=None):
    """A scene file's data (anim/schema.py) for a whole FBX file, and notes
    on what came from the file and what from frustrace's defaults."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(path, "", "file not found")
    worker, info = open_fbx(path, path, "")
    if not info["parts"]:
        raise SceneError(path, "", "the file has no mesh")
    fps = info["fps"] if info["fps"] > 0 else 24.0
    notes = ["FBX file: read Y up in metres"]
    takes = info["takes"]
    played = sorted({k for part in info["parts"]
                     for k in [take_of(part["drivers"], takes, range(len(takes)))[0]] if k is not None})
    start, end = _frames(takes, played, fps, notes)
    cam, res = _camera(worker, info, camera, start, end, fps, path, notes)
    rest = np.concatenate([np.asarray(p["rest"]).reshape(-1, 3) for p in info["parts"]])
    lo, hi = rest.min(axis=0), rest.max(axis=0)
    if cam is None:
        centre, size = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) or 1.0
        cam = {"eye": _vec(centre + [0, 0, 1.6 * size]), "look_at": _vec(centre), "up": [0.0, 1.0, 0.0],
               "fov": 40.0}
        res = [DEFAULT_WIDTH, DEFAULT_WIDTH]
        notes.append("no camera in the file: frustrace's default view of the meshes' bounds")
    lights = _lights(worker, info, start / fps, notes)
    if lights:
        notes.append(f"{len(lights)} light(s) from the file")
    else:
        eye = np.array(cam["eye"] if "eye" in cam else cam["keys"][0]["eye"])
        d2 = float(np.sum(((lo + hi) / 2 - eye) ** 2)) or 1.0
        lights = [{"type": "point", "position": _vec(eye), "intensity": d2}]
        notes.append("no lights in the file: a point light at the camera")
    objects = [{"name": path.stem, "mesh": path.name, **({"animation": "all"} if takes else {})}]
    data = {"version": 1, "frames": {"start": start, "end": end, "fps": float(fps)},
            "output": {"resolution": res}, "camera": cam, "lights": lights, "objects": objects}
    return data, notes
