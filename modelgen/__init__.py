"""modelgen: equations of motion of tree-shaped multibody systems as fast, compiled C.

>>> import modelgen
>>> cm = modelgen.load("models/double_pendulum.yaml")          # doctest: +SKIP
>>> cm.rhs(0.0, [0.1, 0.2, 0.0, 0.0])                           # doctest: +SKIP
"""
from __future__ import annotations

__version__ = "0.1.0"

from .errors import (BuildError, DerivationError, ModelError, ModelgenError,  # noqa: E402
                     SimulationError, TemplateError)

__all__ = ["load", "load_scene", "generate_model", "ModelgenError", "ModelError", "BuildError",
           "DerivationError", "SimulationError", "TemplateError", "__version__"]


def as_spec(source):
    """A :class:`~modelgen.spec.ModelSpec` from a path, a ``Model`` or a spec."""
    from pathlib import Path

    from .spec import ModelSpec
    if isinstance(source, ModelSpec):
        return source
    if isinstance(source, (str, Path)):
        from .model import load_model
        return load_model(source)
    if hasattr(source, "spec"):
        return source.spec()
    raise TypeError(f"cannot make a model from {type(source).__name__}; "
                    "give a YAML path, a modelgen.model.Model or a ModelSpec")


def generate_model(source, out_dir=None, *, force: bool = False, jacobian: bool = False):
    """Generate and compile a model (or reuse the cache); returns the report."""
    from .pipeline import generate
    return generate(as_spec(source), out_dir, force=force, jacobian=jacobian)


def load(source, out_dir=None, *, force: bool = False, jacobian: bool = False):
    """Build (on first use) and import a model; returns a ``CompiledModel``.

    ``source`` is a YAML path, a :class:`modelgen.model.Model` or a ModelSpec.
    Output goes to ``out_dir`` (default ``generated/<name>``).  With
    ``jacobian=True`` the symbolic Jacobian ``<name>_jacobian`` is generated too
    (for stiff integrators; it costs generation and compile time).
    """
    from .runtime import CompiledModel, check_mass_matrix
    generated = generate_model(source, out_dir, force=force, jacobian=jacobian)
    cm = CompiledModel(generated.manifest, generated.build.module_path)
    if not generated.build.cached:
        check_mass_matrix(cm)
    return cm


def load_scene(path, out_dir=None, *, force: bool = False, progress=None):
    """Load a scene file and build its reduced model; returns a ``Scene``.

    Only the effects and outputs the scene selects are generated.  Output goes
    to ``out_dir`` (default ``generated/<scene name>``).

    >>> res = modelgen.load_scene("models/scenes/dp_damped.yaml").run()   # doctest: +SKIP
    """
    from .scene import load_scene as load_scene_spec
    from .simulate import Scene
    return Scene(load_scene_spec(path), out_dir, force=force, progress=progress)


def is_scene_file(path) -> bool:
    """True if a YAML file is a scene (it has a top-level ``scene:`` key)."""
    import re
    from pathlib import Path
    try:
        text = Path(path).read_text()
    except OSError:
        return False
    return re.search(r"^scene\s*:", text, re.MULTILINE) is not None
