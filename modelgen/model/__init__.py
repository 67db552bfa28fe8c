"""Model stage: YAML text or the Python API -> frozen :class:`ModelSpec` / :class:`SceneSpec`.

Input: a model or scene file (untrusted text) or calls on :class:`Model`.
Output: immutable specs (``spec.py``) that every later stage reads and none
mutates.  Nothing here knows of sympy derivations, C or compilers.  The file
format is documented in ``docs/model-format.md``; the modules, and how to add
an effect kind, an output kind or a top-level key, in ``README.md`` here.
"""
from __future__ import annotations

import importlib
import re
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from modelgen.model.spec import ModelSpec

#: Public name -> the module defining it, imported on first use (PEP 562): the
#: readers need sympy (about a second of imports), and a cached load or scene
#: imports this package without reading a model.
_LAZY = {"Model": "api", "load_model": "api", "parse_model": "api", "API_FILE": "messages",
         "check_name": "names", "load_scene": "scene", "parse_scene": "scene",
         "CONSERVATIVE_KINDS": "spec", "EFFECT_FIELD_ROLES": "spec", "EFFECT_KINDS": "spec",
         "EFFECT_TYPES": "spec", "STIFF_KINDS": "spec", "ModelSpec": "spec",
         "SceneSpec": "spec", "load_mjcf": "mjcf", "load_urdf": "urdf",
         "spec_to_yaml": "writer"}

__all__ = ["Model", "ModelSpec", "SceneSpec", "load_model", "parse_model", "spec_to_yaml",
           "check_name", "load_scene", "parse_scene", "as_spec", "is_scene_file", "is_scene_text",
           "API_FILE",
           "EFFECT_TYPES", "EFFECT_KINDS", "EFFECT_FIELD_ROLES", "STIFF_KINDS",
           "CONSERVATIVE_KINDS", "load_urdf", "load_mjcf"]


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list:
    return sorted(set(globals()) | set(__all__))


def as_spec(source, *, floating_base: bool = False, inertia: str = "physical",
            min_mass: float = 0.0, min_inertia: float = 0.0,
            mimic: str = "strict") -> ModelSpec:
    """A :class:`ModelSpec` from a path (YAML, URDF by its ``.urdf`` suffix, MJCF by
    ``.xml``: compiled by MuJoCo, see :mod:`modelgen.model.mjcf`), a
    :class:`Model` or a spec.  ``floating_base=True`` (URDF only) makes the
    root link a free body; ``inertia="as_is"`` or ``"balance"``, ``min_mass`` and
    ``min_inertia`` (URDF only) read bodies that no rigid body matches, and
    ``mimic="ignore"`` (URDF only) reads mimic joints as joints of their own (see
    :mod:`modelgen.model.urdf`)."""
    from modelgen.model.api import Model, load_model
    from modelgen.model.spec import ModelSpec
    urdf = isinstance(source, (str, Path)) and Path(source).suffix.lower() == ".urdf"
    if floating_base and not urdf:
        raise TypeError("floating_base=True applies to a URDF file (a .urdf path); in a "
                        "model file, declare a free joint under 'joints:'")
    if (inertia != "physical" or min_mass or min_inertia or mimic != "strict") and not urdf:
        raise TypeError("inertia=, min_mass=, min_inertia= and mimic= apply to a URDF file "
                        "(a .urdf "
                        "path); a model file gives its bodies' values itself")
    if isinstance(source, ModelSpec):
        return source
    if isinstance(source, (str, Path)):
        if Path(source).suffix.lower() == ".urdf":
            from modelgen.model.urdf import load_urdf
            return load_urdf(source, floating_base=floating_base, inertia=inertia,
                             min_mass=min_mass, min_inertia=min_inertia, mimic=mimic).spec()
        if Path(source).suffix.lower() == ".xml":
            from modelgen.model.mjcf import load_mjcf
            return load_mjcf(source).spec()
        return load_model(source)
    if isinstance(source, Model):
        return source.spec()
    raise TypeError(f"cannot make a model from {type(source).__name__}; "
                    "give a YAML path, a modelgen.model.Model or a ModelSpec")


#: a block mapping's top-level key ``scene``, plain or quoted, at the start of a line
_SCENE_KEY = re.compile(r"""^(?:scene|"scene"|'scene')[ \t]*:(?=[ \t\r\n]|\Z)""", re.MULTILINE)


def is_scene_file(path) -> bool:
    """True if a YAML file is a scene (it has a top-level ``scene:`` key); see
    :func:`is_scene_text`."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return False
    return is_scene_text(text)


def is_scene_text(text: str) -> bool:
    """True if YAML text has a top-level ``scene`` key: a plain or quoted key at the
    start of a line (after a UTF-8 byte order mark, if any), or a key of a document
    that is one flow mapping (``{scene: s, model: m.yaml, ...}``) or starts with an
    explicit key, read with the safe YAML reader (which a scene run from its
    cached card never imports otherwise)."""
    text = text.removeprefix("\ufeff")
    if _SCENE_KEY.search(text):
        return True
    if "scene" not in text or _first_token(text) not in ("{", "?"):
        return False
    from modelgen.errors import ModelError
    from modelgen.model.reader import compose
    try:
        data, _ = compose(text, "<text>")
    except ModelError:
        return False
    return isinstance(data, dict) and "scene" in data


def _first_token(text: str) -> str:
    """The first character of a YAML document's content, past blank and comment lines,
    directives and a ``---`` marker ('' for none)."""
    for line in text.splitlines():
        content = line.strip()
        if content.startswith("---"):
            content = content[3:].strip()
        if content and not content.startswith(("#", "%")):
            return content[0]
    return ""
