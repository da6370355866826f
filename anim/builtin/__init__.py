"""Built-in scenes (`frustrace assets`): SCENES are generated on demand,
deterministic, and know their exact motion (`exact(t)`) for interpolation
error studies; the demo ships as files (demo.py). ALL holds both."""
from .demo import DemoScene
from .fairy import FairyScene
from .hand import HandScene
from .marbles import MarblesScene
from .runner import RunnerScene
from .toys import ToysScene
from .torus import TorusScene

SCENES = {s.name: s for s in (HandScene, RunnerScene, ToysScene, MarblesScene, FairyScene, TorusScene)}
ALL = {"demo": DemoScene, **SCENES}


def get(name):
    """A fresh instance of the built-in scene `name`, demo included (KeyError if unknown)."""
    return ALL[name]()
