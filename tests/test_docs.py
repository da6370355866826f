"""The scene-file reference (docs/scene-format.md) stays true: its examples
validate, and every key the schema knows is documented there."""
import re
import typing
from pathlib import Path

import yaml
from pydantic import BaseModel

from anim import schema

DOC = Path(__file__).resolve().parent.parent / "docs" / "scene-format.md"


def test_every_example_validates():
    blocks = re.findall(r"```yaml\n(.*?)```", DOC.read_text(), re.S)
    assert len(blocks) >= 3
    for block in blocks:
        schema.parse_scene(yaml.safe_load(block))


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


def test_the_readme_links_the_reference():
    readme = (DOC.parent.parent / "README.md").read_text()
    assert "docs/scene-format.md" in readme
