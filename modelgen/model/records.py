"""What a scene records and feeds, as plain values: no sympy.

:class:`OutputSpec` and :class:`InputSignal` are parts of a
:class:`~modelgen.model.spec.SceneSpec`, and also of the scene card that a
cached scene runs from without reading its model (:mod:`modelgen.sim.scene`),
so they live here, importable without the symbolic packages.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional


@dataclass(frozen=True)
class OutputSpec:
    """One recorded output of a scene: ``kind`` with its resolved arguments."""
    name: str
    kind: str               # a key of modelgen.model.spec.OUTPUT_KINDS
    args: tuple             # ((key, value), ...) with every key of the kind, defaults filled

    def arg(self, key):
        return dict(self.args)[key]


@dataclass(frozen=True)
class InputSignal:
    """An input's value at run time: a constant, or samples in time.

    ``times``/``values`` are increasing sample times and the values there;
    ``interpolation`` is ``"linear"`` or ``"hold"`` (zero-order hold); before
    the first and after the last sample the end values are held.
    """
    name: str
    constant: Optional[float] = None
    times: tuple = ()
    values: tuple = ()
    interpolation: str = "linear"
