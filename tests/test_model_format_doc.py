"""docs/model-format.md: every YAML example is valid, and every kind is documented.

Blocks marked ```yaml model are complete model files and ```yaml scene
complete scene files (model paths relative to docs/): each is loaded.
```yaml fragment blocks are excerpts: each must at least be YAML.  An
unmarked ```yaml block is an error, so no example escapes the check.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from modelgen.model import parse_model, parse_scene
from modelgen.model.spec import EFFECT_KINDS, OUTPUT_KINDS, ModelSpec
from modelgen.model.scene import TOP_LEVEL_KEYS as SCENE_KEYS
from modelgen.model.schema import TOP_LEVEL_KEYS as MODEL_KEYS

DOC = Path(__file__).resolve().parent.parent / "docs" / "model-format.md"
TEXT = DOC.read_text()
BLOCKS = [(m.group(1).strip(), m.group(2), TEXT.count("\n", 0, m.start()) + 1)
          for m in re.finditer(r"```yaml([^\n]*)\n(.*?)```", TEXT, re.DOTALL)]


def _ids(kind):
    return [f"line{line}" for marker, _, line in BLOCKS if marker == kind]


def test_every_yaml_block_is_marked():
    markers = {marker for marker, _, _ in BLOCKS}
    assert markers <= {"model", "scene", "fragment"}, markers
    assert len([b for b in BLOCKS if b[0] == "model"]) >= 10


@pytest.mark.parametrize("text", [t for m, t, _ in BLOCKS if m == "model"], ids=_ids("model"))
def test_model_examples_load(text):
    assert isinstance(parse_model(text, source=str(DOC)), ModelSpec)


@pytest.mark.parametrize("text", [t for m, t, _ in BLOCKS if m == "scene"], ids=_ids("scene"))
def test_scene_examples_load(text):
    scene = parse_scene(text, source=str(DOC), base_dir=DOC.parent)
    assert scene.outputs or scene.effects


@pytest.mark.parametrize("text", [t for m, t, _ in BLOCKS if m == "fragment"],
                         ids=_ids("fragment"))
def test_fragments_are_yaml(text):
    assert yaml.safe_load(text) is not None


def test_every_kind_key_and_output_is_documented():
    effect_types = {e.kind for m, t, _ in BLOCKS if m == "model" for e in parse_model(t).effects}
    assert effect_types == set(EFFECT_KINDS)
    for kind in EFFECT_KINDS:
        assert f"### {kind}" in TEXT, kind
    scenes = [parse_scene(t, base_dir=DOC.parent) for m, t, _ in BLOCKS if m == "scene"]
    assert {o.kind for s in scenes for o in s.outputs} == set(OUTPUT_KINDS)
    for kind, options in OUTPUT_KINDS.items():
        row = next(line for line in TEXT.splitlines() if line.startswith(f"| `{kind}` |"))
        for option in options[1:]:
            assert f"`{option}`" in row, (kind, option)
    for key in MODEL_KEYS + SCENE_KEYS:
        assert f"| `{key}` |" in TEXT, key
