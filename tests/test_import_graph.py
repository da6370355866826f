"""The package's imports form layers that point down, with no cycle: a
module may import from its own sub-package or from a lower layer, never from
a sibling of its layer or from above (raycore/__init__.py lists the layers).
Lazy imports inside functions count too: a cycle hidden in one is a cycle."""
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("raycore", "anim", "cli")

# layer of each part of the tree; an import must go to a lower layer or stay
# inside its own part. Parts are matched by their longest dotted prefix.
LAYERS = {
    "raycore": -1,
    "raycore.config": 0, "raycore.jit": 0,
    "raycore.geometry": 1, "raycore.images": 1,
    "raycore.grid": 2, "raycore.kdtree": 2, "raycore.bvh": 2,
    "raycore.shading": 3,
    "raycore.accelerators": 4, "raycore.adaptive": 4, "raycore.sweep": 4, "raycore.instancing": 4,
    "raycore.structures": 5, "raycore.pass_scene": 6,
    "raycore.frame": 7,
    "anim": 10,                       # interpolation, rigs, materials, the kernels that move vertices
    "anim.io": 11,                    # the file readers (meshes, glTF, USD, the mesh cache)
    "anim.schema": 12, "anim.scene": 13,
    "anim.builtin": 14, "anim.render": 14,
    "anim.measure": 15,
    "cli": 20,
}


def modules() -> dict:
    """{dotted module name: path} of every module of the packages."""
    found = {}
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            found[name] = path
    return found


def imports_of(name: str, path: Path, known: dict) -> set:
    """The package modules `name` imports, at any depth of its code."""
    out = set()
    is_pkg = path.name == "__init__.py"
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = name.split(".")[:len(name.split(".")) - node.level + (1 if is_pkg else 0)]
                base = ".".join(parent + ([base] if base else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
        else:
            continue
        out |= {t for t in targets if t in known and t != name}
    return out


def graph() -> dict:
    known = modules()
    return {name: imports_of(name, path, known) for name, path in known.items()}


def part_of(name: str) -> str:
    """The part of the tree `name` belongs to: the longest entry of LAYERS
    that is it or a package above it ("raycore" itself: only the package's
    own module, which holds nothing but its version)."""
    if name == "raycore":
        return name
    best = ""
    for part in LAYERS:
        if part == "raycore":
            continue
        if (name == part or name.startswith(part + ".")) and len(part) > len(best):
            best = part
    return best


def find_cycle(edges: dict):
    """One cycle (a list of modules) or None: depth-first, three colours."""
    colour, stack = {}, []

    def visit(n):
        colour[n] = 1
        stack.append(n)
        for m in sorted(edges.get(n, ())):
            if colour.get(m) == 1:
                return stack[stack.index(m):] + [m]
            if m not in colour:
                found = visit(m)
                if found:
                    return found
        stack.pop()
        colour[n] = 2
        return None
    for n in sorted(edges):
        if n not in colour:
            found = visit(n)
            if found:
                return found
    return None


def layer_violations(edges: dict) -> list:
    bad = []
    for a, targets in edges.items():
        pa = part_of(a)
        for b in targets:
            pb = part_of(b)
            if pa != pb and not LAYERS[pb] < LAYERS[pa]:
                bad.append(f"{a} ({pa}, layer {LAYERS[pa]}) imports {b} ({pb}, layer {LAYERS[pb]})")
    return sorted(bad)


def test_every_module_has_a_layer():
    assert [n for n in modules() if n not in PACKAGES and not part_of(n)] == []


def test_the_imports_have_no_cycle():
    assert find_cycle(graph()) is None


def test_every_import_points_down():
    assert layer_violations(graph()) == []


def test_the_checks_see_a_cycle_and_an_upward_import():
    """The checks can fail: a made-up cycle and an import from the grid
    into the shading layer, and one between two sibling structures."""
    edges = graph()
    assert edges["raycore.grid.trace"] and "raycore.jit.presets" in edges["raycore.grid.cgt"]
    looped = {**edges, "raycore.jit.presets": edges["raycore.jit.presets"] | {"raycore.grid.cgt"}}
    assert find_cycle(looped) is not None
    upward = {**edges, "raycore.grid.trace": edges["raycore.grid.trace"] | {"raycore.shading.surface"}}
    assert any("raycore.grid.trace" in v for v in layer_violations(upward))
    sideways = {**edges, "raycore.grid.trace": edges["raycore.grid.trace"] | {"raycore.bvh.scene"}}
    assert any("raycore.bvh.scene" in v for v in layer_violations(sideways))
