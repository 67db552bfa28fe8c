"""modelgen: equations of motion of tree-shaped multibody systems as fast, compiled C.

The package is a pipeline of stages, each a subpackage, imports running down
the line only: ``model`` (text, API -> spec) -> ``derive`` (spec -> program)
-> ``codegen`` (program -> C -> module) -> ``sim`` (module -> trajectories)
-> ``bench`` -> ``cli``.  This module only re-exports the front door, lazily,
so ``import modelgen`` stays cheap.

>>> import modelgen
>>> cm = modelgen.load("models/double_pendulum.yaml")          # doctest: +SKIP
>>> cm.rhs(0.0, [0.1, 0.2, 0.0, 0.0])                           # doctest: +SKIP
"""
from __future__ import annotations

from modelgen.errors import (BuildError, DerivationError, MassMatrixError, ModelError,
                             ModelgenError, SimulationError, TemplateError)
from modelgen.version import __version__

__all__ = ["load", "load_scene", "generate_model", "as_spec", "is_scene_file", "sweep", "grid",
           "Model", "ModelgenError", "ModelError", "BuildError", "DerivationError", "SimulationError",
           "MassMatrixError", "TemplateError", "__version__"]

#: public name -> the module that defines it (imported on first use)
_LAZY = {"load": "modelgen.sim.load", "load_scene": "modelgen.sim.load",
         "generate_model": "modelgen.sim.load", "as_spec": "modelgen.model",
         "is_scene_file": "modelgen.model", "sweep": "modelgen.sim.sweep",
         "grid": "modelgen.sim.sweep", "Model": "modelgen.model"}


def __getattr__(name):
    if name in _LAZY:
        import importlib
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'modelgen' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
