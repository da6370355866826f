"""Built-in scenes (`frustrace assets`), generated on demand and deterministic.
Each knows its exact motion (`exact(t)`) for interpolation error studies."""
from .fairy import FairyScene
from .hand import HandScene
from .marbles import MarblesScene
from .runner import RunnerScene
from .toys import ToysScene
from .torus import TorusScene

SCENES = {s.name: s for s in (HandScene, RunnerScene, ToysScene, MarblesScene, FairyScene, TorusScene)}


def get(name):
    """A fresh instance of the built-in scene `name` (KeyError if unknown)."""
    return SCENES[name]()
