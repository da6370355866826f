"""A faster equality for numba's compile flags, the same answers.

numba keeps the typed implementation of every overloaded function (np.empty,
min, abs, ...) in a cache keyed by the argument types and the compile's
flags (numba.core.targetconfig.TargetConfig). The flags hash to the same
value whatever they are set to (the hash is over the option names), so
every lookup ends in __eq__, which builds a dict of all ~40 options of
each side through their properties. A cold compile of the demo makes
~180,000 such comparisons; this saves ~5 % of it (docs/performance.md).

Here equality compares only the options that either side has set (an option
neither has set is at its default on both), and the hash, still over the
sorted option names, is computed once per class. Should numba's internals
move (no `options` or `_values`), nothing is changed.
"""
from numba.core import targetconfig

_TargetConfig = getattr(targetconfig, "TargetConfig", None)
_HASHES = {}


def _equal(self, other):
    """self.values() == other.values(), without building either."""
    if not isinstance(other, _TargetConfig):
        return NotImplemented
    options = self.options
    if options is not other.options:                # different kinds of flags: numba's own test
        return self.values() == other.values()
    mine, theirs = self._values, other._values
    for name in mine.keys() | theirs.keys():
        default = options[name].default
        a, b = mine.get(name, default), theirs.get(name, default)
        if not (a is b or a == b):                   # as a dict compares its values
            return False
    return True


def _hash(self):
    """hash(tuple(sorted(self.values()))), numba's own: over the option
    names (sorting a dict sorts its keys), so once per class."""
    kind = type(self)
    h = _HASHES.get(kind)
    if h is None:
        h = _HASHES[kind] = hash(tuple(sorted(self.options)))
    return h


def install():
    """Put _equal and _hash on numba's TargetConfig (once)."""
    if _TargetConfig is None or _TargetConfig.__eq__ is _equal:
        return
    if not (hasattr(_TargetConfig, "options") and "_values" in getattr(_TargetConfig, "__slots__", ())):
        return
    _TargetConfig.original_eq, _TargetConfig.original_hash = _TargetConfig.__eq__, _TargetConfig.__hash__
    _TargetConfig.__eq__ = _equal
    _TargetConfig.__hash__ = _hash


install()
