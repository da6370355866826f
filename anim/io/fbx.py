"""FBX objects (`mesh: char.fbx`): meshes, skinning, blend shapes and node
animation as ufbx evaluates them, with the file's takes chosen by
`animation:` (a name or an index, the first by default; `all` or a list
of takes: each part moves as the take that animates it, see take_of).

ufbx (the official binding of the ufbx C library) runs in a process of its
own (fbx_worker.py): the binding can crash the interpreter, and a crash
there is one line and exit 2 here. The file is read Y up in metres
(`target_axes` right-handed Y up, `target_unit_meters` 1), as glTF is; a
take's time t is scene time t (frame f at f / fps). Skinned, blend-shaped
positions are ufbx's (`evaluate_scene(..., evaluate_skinning=True)`), in
world space through each instance's geometry-to-world transform.
"""
import atexit
import os
from pathlib import Path
import pickle
import struct
import subprocess
import sys

import numpy as np

from anim.errors import SceneError
from anim.interpolate import wrap_time
from anim.io.polygons import split_at_seams, triangulate
from anim.materials import pbr_material

_OPEN = {}        # resolved path -> (mtime, worker process, its "open" answer): one read per file and change


def _stop_workers():
    for _, proc, _ in _OPEN.values():
        _close(proc)


atexit.register(_stop_workers)


def open_fbx(path, scene_path, key):
    """(FbxWorker, what the file holds) for an FBX file, its process started
    and the file read once per file and change (a whole-file render reads
    it for the scene's camera and lights, then for its meshes)."""
    resolved = str(Path(path).resolve())
    mtime = Path(path).stat().st_mtime_ns
    cached = _OPEN.get(resolved)
    if cached is not None and cached[0] == mtime and cached[1].poll() is None:
        return FbxWorker(cached[1], path, scene_path, key), cached[2]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [_package_root(), os.environ.get("PYTHONPATH")]))}
    proc = subprocess.Popen([sys.executable, "-m", "anim.io.fbx_worker"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env)
    worker = FbxWorker(proc, path, scene_path, key)
    try:
        info = worker.call("open", resolved)
    except SceneError:
        _close(proc)
        raise
    if cached is not None:
        _close(cached[1])
    _OPEN[resolved] = (mtime, proc, info)
    return worker, info


def _close(proc):
    if proc.poll() is None:
        try:
            proc.stdin.close()
            proc.wait(timeout=5)
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()


class FbxWorker:
    """An FBX file's worker process, as one scene key asks it (its errors name that key)."""

    def __init__(self, proc, path, scene_path, key):
        self.proc, self.path, self.scene_path, self.key = proc, path, scene_path, key

    def call(self, op, *args):
        """The worker's answer to (op, args); SceneError (exit 2) if it fails or dies."""
        try:
            data = pickle.dumps((op, args))
            self.proc.stdin.write(struct.pack("<Q", len(data)) + data)
            self.proc.stdin.flush()
            head = self.proc.stdout.read(8)
            if len(head) < 8:
                raise EOFError
            (n,) = struct.unpack("<Q", head)
            status, value = pickle.loads(self.proc.stdout.read(n))
        except (BrokenPipeError, EOFError, OSError, pickle.UnpicklingError):
            code = self.proc.poll()
            raise SceneError(self.scene_path, self.key, f"{self._name}the FBX reader (ufbx) stopped "
                                                        f"reading it (exit {code}): a malformed file") from None
        if status != "ok":
            raise SceneError(self.scene_path, self.key, f"{self._name}cannot read FBX: {value}")
        return value

    @property
    def _name(self):
        """The file's name to start a message with, unless the error already names it."""
        return "" if Path(self.scene_path) == Path(self.path) else f"{Path(self.path).name}: "


def take_of(drivers, takes, allowed):
    """(the take that moves an element, a note or None): among the `allowed`
    takes, those that animate one of its `drivers` ({node id: name}: its
    node, bones and their ancestors). Several: the one named
    "<driver>|<driver>Action" (Blender writes a take per object and every
    action that fits it, and an object's own action is "<object>Action"),
    else the first, with a note naming the others. None: no take moves it."""
    movers = [k for k in allowed if set(drivers) & set(takes[k]["nodes"])]
    if len(movers) <= 1:
        return (movers[0] if movers else None), None
    names = {n for n in drivers.values() if n}
    own = [k for k in movers if takes[k]["name"] in {f"{n}|{n}Action" for n in names}]
    if own:
        return own[0], None
    return movers[0], (f"moved by {len(movers)} takes ({', '.join(takes[k]['name'] for k in movers)}); the first "
                       "plays (a list of takes under 'animation:' chooses)")


def _package_root():
    """The folder that holds the `anim` package, for the worker's imports."""
    import anim
    return os.path.dirname(os.path.dirname(os.path.abspath(anim.__file__)))


class FbxObject:
    """Geometry and motion of one FBX file; `place(t, out, transform)` writes
    the posed vertices (n, 3) f32."""

    def __init__(self, path, animation, extrapolate, scene_path, key, warnings=None):
        self.path, self.scene_path, self.key, self.extrapolate = path, scene_path, key, extrapolate
        warnings = warnings if warnings is not None else []
        if not path.is_file():
            raise SceneError(scene_path, key, f"mesh file not found: {path}")
        self.worker, info = open_fbx(path, scene_path, key)
        parts = info["parts"]
        if not parts:
            raise SceneError(scene_path, key, f"{path.name}: the file has no mesh")
        self.takes = info["takes"]
        self.take_of_part = self._takes(parts, animation, warnings)
        faces, rests, slots, uvs, gather, offset, unsplit = [], [], [], [], [], 0, 0
        for part in parts:
            rest = np.asarray(part["rest"], np.float64)
            counts = part["faces"][:, 1]
            order = np.concatenate([np.arange(b, b + n) for b, n in part["faces"]]) if len(counts) else \
                np.zeros(0, np.int64)
            index = part["index"]
            if len(order) and (order.max() >= len(index) or order.min() < 0 or
                               (len(index) and (index.max() >= len(rest) or index.min() < 0))):
                raise SceneError(scene_path, key, f"{path.name}: mesh {part['name']!r} has a face index "
                                                  f"beyond its {len(rest)} vertices")
            tri, corner, poly = triangulate(counts, index[order], rest)
            point_of = np.arange(len(rest))
            uv = np.zeros((len(rest), 2))
            seams = []                     # per-corner values whose changes split a point
            if part["uv"] is not None:
                seams.append(np.asarray(part["uv"])[order[corner.reshape(-1)]])
            if part.get("normals") is not None:
                # the file's normals where they differ between one point's corners (hard edges);
                # a normal id per distinct direction (rounded: the same normal written twice)
                _, ids = np.unique(np.round(np.asarray(part["normals"]), 6), axis=0, return_inverse=True)
                seams.append(ids.reshape(-1)[order[corner.reshape(-1)]][:, None].astype(np.float64))
            if seams:
                # a vertex per distinct (point, uv, normal): points split only along seams
                point_of, kept, tri = split_at_seams(tri, *seams)
                if part["uv"] is not None:
                    uv = kept[:, :2]
            faces.append(tri + offset)
            slots.append(part["face_material"][poly] if len(part["face_material"]) else np.full(len(tri), -1))
            rests.append(rest[point_of])
            uvs.append(uv)
            gather.append(point_of + unsplit)
            offset += len(point_of)
            unsplit += len(rest)
        self.faces = np.ascontiguousarray(np.concatenate(faces), np.int32)
        self.face_material = np.concatenate(slots).astype(np.int64)
        self.rest = np.concatenate(rests)
        self.part_rest = [np.asarray(p["rest"], np.float64) for p in parts]   # unsplit, for parts left at rest
        self.gather = np.concatenate(gather)           # output vertex -> the worker's (unsplit) point
        if not np.all(np.isfinite(self.rest)):
            raise SceneError(scene_path, key, f"{path.name}: inf or NaN among the mesh's points")
        self.uvs = np.concatenate(uvs).astype(np.float32)
        self.materials = {}
        self.texture_files = []            # the image files it reads (they travel with it to a cluster)
        for m in info["materials"]:
            self.materials[m["slot"]] = pbr_material(f"{path.name}:{m['name']}", m["colour"], m["roughness"],
                                                     m["metallic"], self._texture(m))
        played = [self.takes[k] for k in set(self.take_of_part) if k is not None]
        self.t0 = min((k["begin"] for k in played), default=0.0)
        self.t1 = max((k["end"] for k in played), default=0.0)
        self.static = not played or self.t1 <= self.t0
        self.rigid = False                      # skinned and blend-shaped meshes deform

    def _texture(self, material):
        """A base-colour texture: the file the FBX names, looked for beside
        the FBX first (files travel with the scene), then where it says;
        else the image embedded in the file; None without one; exit 2 when
        named but found nowhere."""
        files = material["texture"]
        if files is None:
            return None
        for name in (files["relative"], files["absolute"]):
            for found in ((self.path.parent / name), (self.path.parent / Path(name).name)):
                if name and Path(name).name and found.is_file():
                    self.texture_files.append(found)
                    return found
        if files["content"]:
            return files["content"], Path(files["relative"] or files["absolute"] or "x.png").suffix or ".png"
        raise SceneError(self.scene_path, self.key, f"{self.path.name}: material {material['name']!r}: texture "
                                                    f"file not found: {files['relative'] or files['absolute']}")

    def _takes(self, parts, which, warnings):
        """The take each part plays (None: at rest): the one `animation:`
        names (the first when unset), or for `all` or a list of takes the
        one that animates the part (take_of)."""
        takes, anim_key = self.takes, self.key.rsplit(".", 1)[0] + ".animation"
        if not takes:
            if which is not None:
                raise SceneError(self.scene_path, anim_key, f"{self.path.name}: animation {which!r} requested, "
                                                            "but the file has no takes")
            return [None] * len(parts)
        names = [t["name"] for t in takes]
        if which is None:
            if len(takes) > 1:
                warnings.append(f"{self.key}: {self.path.name} has {len(takes)} takes ({', '.join(names)}); "
                                f"the first plays ('animation:' chooses, key {anim_key}: a take, or all)")
            return [0] * len(parts)
        if which == "all" or isinstance(which, list):
            allowed = range(len(takes)) if which == "all" else [self._take_index(w, names, anim_key) for w in which]
            chosen = []
            for part in parts:
                k, note = take_of(part["drivers"], takes, allowed)
                chosen.append(k)
                if note:
                    warnings.append(f"{anim_key}: {self.path.name}: mesh {part['name']!r}: {note}")
            return chosen
        return [self._take_index(which, names, anim_key)] * len(parts)

    def _take_index(self, which, names, anim_key):
        if isinstance(which, int) and not isinstance(which, bool):
            if 0 <= which < len(names):
                return which
        elif which in names:
            return names.index(which)
        raise SceneError(self.scene_path, anim_key, f"{self.path.name}: no take {which!r}; its takes: "
                                                    f"{', '.join(f'{i} ({n!r})' for i, n in enumerate(names))}")

    def place(self, t, out, transform=None):
        """Posed vertices at scene time t into out (n, 3) f32; `transform` (3, 4) on top."""
        if self.static:
            pts = self.rest
        else:
            moved = self.worker.call("evaluate", self.take_of_part, wrap_time(t, self.t0, self.t1, self.extrapolate))
            pts = np.concatenate([rest if p is None else np.asarray(p) for p, rest in zip(moved, self.part_rest)])
            pts = pts[self.gather]
            if pts.shape != self.rest.shape or not np.all(np.isfinite(pts)):
                raise SceneError(self.scene_path, self.key, f"{self.path.name}: the evaluated mesh at t = {t:g} "
                                                            "has inf or NaN points, or another vertex count")
        if transform is not None:
            pts = pts @ np.asarray(transform)[:, :3].T + np.asarray(transform)[:, 3]
        out[...] = pts
