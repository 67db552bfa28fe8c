"""Model stage: YAML text or the Python API -> frozen :class:`ModelSpec` / :class:`SceneSpec`.

Input: a model or scene file (untrusted text) or calls on :class:`Model`.
Output: immutable specs (``spec.py``) that every later stage reads and none
mutates.  Nothing here knows of sympy derivations, C or compilers.
"""
from __future__ import annotations

import re
from pathlib import Path

from modelgen.model.api import (API_FILE, EFFECT_FIELD_ROLES, EFFECT_KINDS, Model, check_name,
                                load_model, parse_model, spec_to_yaml)
from modelgen.model.scene import load_scene, parse_scene
from modelgen.model.spec import ModelSpec
from modelgen.model.urdf import load_urdf

__all__ = ["Model", "ModelSpec", "load_model", "parse_model", "spec_to_yaml", "check_name",
           "load_scene", "parse_scene", "as_spec", "is_scene_file", "API_FILE",
           "EFFECT_KINDS", "EFFECT_FIELD_ROLES"]


def as_spec(source) -> ModelSpec:
    """A :class:`ModelSpec` from a path (YAML, or URDF by its ``.urdf`` suffix), a
    :class:`Model` or a spec."""
    if isinstance(source, ModelSpec):
        return source
    if isinstance(source, (str, Path)):
        if Path(source).suffix.lower() == ".urdf":
            return load_urdf(source).spec()
        return load_model(source)
    if isinstance(source, Model):
        return source.spec()
    raise TypeError(f"cannot make a model from {type(source).__name__}; "
                    "give a YAML path, a modelgen.model.Model or a ModelSpec")


def is_scene_file(path) -> bool:
    """True if a YAML file is a scene (it has a top-level ``scene:`` key)."""
    try:
        text = Path(path).read_text()
    except (OSError, UnicodeDecodeError):
        return False
    return re.search(r"^scene\s*:", text, re.MULTILINE) is not None
