"""Run as a script in a fresh process (tests/render/test_warm_up.py): warm_up, then
three frames rendered and written; prints the numba kernels that compiled
(or loaded) a new specialisation after warm_up: none may."""
import sys, tempfile
sys.path.insert(0, str(__import__('pathlib').Path(__file__).resolve().parent.parent))
from anim.scene import AnimatedScene
from anim.render.renderer import SceneRenderer
from anim.render.warm_up import warm_up
from anim.render.settings import config_of, shading_of
from raycore.images.image_io import write_exr

def signatures():
    import numba.core.registry as reg
    out = {}
    for name, mod in list(sys.modules.items()):
        if not name.startswith(("raycore", "anim")):
            continue
        for attr, obj in list(vars(mod).items()):
            if isinstance(obj, reg.CPUDispatcher):
                out[f"{name}.{attr}"] = len(obj.signatures)
    return out

scene = AnimatedScene(sys.argv[1])
kw = eval(sys.argv[2]) if len(sys.argv) > 2 else {}
cfg = config_of(scene, width=64, height=48, **kw)
shading = shading_of(scene)
warm_up(scene, shading, cfg, scene.time_of(0))
before = signatures()
r = SceneRenderer(scene, cfg, shading)
with tempfile.TemporaryDirectory() as tmp:
    for f in (0, 1, 2):
        _, res = r.render(scene.time_of(f))
        write_exr(f"{tmp}/f.exr", {"RGBA": res.rgba, "Z": res.z, **res.aovs}, {}, scene.spec.output.compression)
after = signatures()
new = {k: after[k] - before.get(k, 0) for k in after if after[k] != before.get(k, 0)}
print("NEW", new)
