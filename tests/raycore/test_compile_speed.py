"""raycore/jit/compile_speed.py: numba's flags compare and hash as numba's own
code would, on random and on adversarial settings (an option set to its
default, options set on one side only, different option values)."""
import random

from numba.core.compiler import Flags
from numba.core.targetconfig import TargetConfig

import raycore.jit.compile_speed  # noqa: F401


def _random_flags(rng, names):
    f = Flags()
    for name in rng.sample(names, rng.randint(0, 6)):
        option = Flags.options[name]
        if option.type is bool:
            setattr(f, name, rng.random() < 0.5)
        elif name == "fastmath":
            setattr(f, name, rng.choice([False, True, {"arcp", "nsz"}, {"contract"}]))
        else:
            setattr(f, name, option.default)       # set explicitly, to its default
    return f


def test_flags_compare_and_hash_as_numbas_own():
    assert TargetConfig.__eq__ is not TargetConfig.original_eq      # installed
    rng = random.Random(3)
    names = sorted(n for n, o in Flags.options.items() if o.type is bool or n == "fastmath")
    flags = [_random_flags(rng, names) for _ in range(300)] + [Flags(), Flags()]
    for a, b in zip(flags, flags[1:] + flags[:1]):
        assert (a == b) == TargetConfig.original_eq(a, b)
        assert hash(a) == TargetConfig.original_hash(a)
    for a in flags[:50]:
        assert a == Flags(a) and a == a and TargetConfig.original_eq(a, Flags(a))
        assert (a == 1) is False
    # explicitly set to the default equals unset
    x, y = Flags(), Flags()
    x.boundscheck = Flags.options["boundscheck"].default
    assert x == y and TargetConfig.original_eq(x, y)
    x.nrt = not Flags.options["nrt"].default
    assert x != y and not TargetConfig.original_eq(x, y)
