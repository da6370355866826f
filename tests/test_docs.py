"""The documentation stays true: every scene example in README.md and docs/
validates, every key the schema knows is documented in the scene-format
reference, the README stays a guide, and the code carries no diaries."""
import re
import typing
from pathlib import Path

import yaml
from pydantic import BaseModel

from anim import schema

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "scene-format.md"
README = ROOT / "README.md"


def yaml_blocks():
    """(file, block) of every ```yaml block of README.md and docs/*.md."""
    for path in [README, *sorted((ROOT / "docs").glob("*.md"))]:
        for block in re.findall(r"```yaml\n(.*?)```", path.read_text(), re.S):
            yield path.name, block


def test_every_yaml_example_in_the_docs_validates():
    blocks = list(yaml_blocks())
    assert len(blocks) >= 4 and {"README.md", "scene-format.md"} <= {name for name, _ in blocks}
    for name, block in blocks:
        try:
            schema.parse_scene(yaml.safe_load(block))
        except Exception as e:                   # name the example that broke
            raise AssertionError(f"{name}: {block[:80]!r}...: {e}") from e


def _models(model, seen):
    if model in seen:
        return
    seen.add(model)
    for field in model.model_fields.values():
        stack = [field.annotation]
        while stack:
            t = stack.pop()
            if isinstance(t, type) and issubclass(t, BaseModel):
                _models(t, seen)
            stack.extend(typing.get_args(t))


def test_every_schema_key_is_documented():
    models = set()
    _models(schema.SceneFile, models)
    text = DOC.read_text()
    missing = sorted({name for m in models for name in m.model_fields if f"`{name}`" not in text})
    assert not missing, f"undocumented keys: {missing}"


def test_the_readme_is_a_guide_that_links_the_reference():
    text = README.read_text()
    assert "docs/scene-format.md" in text
    assert len(text.splitlines()) <= 400
    for link in re.findall(r"\]\((docs/[\w.-]+\.md)\)", text):
        assert (ROOT / link).is_file(), link


def test_the_code_carries_no_dates_or_issue_numbers():
    """Measurements and their history go to docs/; the code says why once."""
    pattern = re.compile(r"20\d\d-\d\d-\d\d|[Ii]ssue \d+")
    found = [f"{p.relative_to(ROOT)}:{i}" for part in ("cli", "anim", "raycore")
             for p in sorted((ROOT / part).rglob("*.py"))
             for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if pattern.search(line)]
    assert found == []


def test_the_design_notes_list_every_module():
    """docs/design.md has a table per package: every module is in it, none that is gone."""
    text = (ROOT / "docs" / "design.md").read_text()
    tables = re.findall(r"^### `([\w/]+)/`\n\n\| module \| what it is \|\n\|---\|---\|\n((?:\|.*\|\n)+)", text, re.M)
    assert len(tables) >= 10
    for pkg, rows in tables:
        listed = set(re.findall(r"^\| `([\w.]+)` \|", rows, re.M)) - {"__init__.py"}
        present = {f.name for f in (ROOT / pkg).glob("*.py")} - {"__init__.py"}
        assert listed == present, (pkg, sorted(present - listed), sorted(listed - present))
