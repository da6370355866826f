"""Built-in scenes (`frustrace assets`): SCENES are generated on demand,
deterministic, and know their exact motion (`exact(t)`) for interpolation
error studies; the demo ships as files (demo.py). ALL holds both."""
from anim.builtin.demo import DemoScene
from anim.builtin.fairy import FairyScene
from anim.builtin.field import FieldScene
from anim.builtin.hand import HandScene
from anim.builtin.marbles import MarblesScene
from anim.builtin.runner import RunnerScene
from anim.builtin.toys import ToysScene
from anim.builtin.torus import TorusScene

SCENES = {s.name: s for s in (HandScene, RunnerScene, ToysScene, MarblesScene, FairyScene, TorusScene,
                                      FieldScene)}
ALL = {"demo": DemoScene, **SCENES}


def get(name):
    """A fresh instance of the built-in scene `name`, demo included (KeyError if unknown)."""
    return ALL[name]()
