"""The library part of the benchmarks: work-precision problems, sweeps, references, plots.

One module per job (see ``modelgen/bench/README.md``): ``problem`` (the data
of a problem and its reference), ``methods`` (the C integrators and
solve_ivp behind one call), ``references`` (closed forms, two-method and
extended-precision references), ``precision_sweep`` (the runner, errors, costs),
``tables``, ``plots``, and ``standard`` (the standard problems, whose scenes
ship in ``problems/``).  The names the CLI and ``bench/work_precision.py``
use are re-exported here, each imported on first use.

>>> from modelgen import bench
>>> bench.tolerance_sweep(1e-2, 1e-4, per_decade=1)
(0.01, 0.001, 0.0001)
"""
from __future__ import annotations

import importlib

#: name -> the module of this package that defines it.  Imported on first use
#: (PEP 562), not here: the whole set pulls in scipy.integrate and matplotlib
#: (seconds), which a benchmark script's ``--help``, the C harnesses
#: (``from modelgen.bench import harnesses``) and a child process that
#: measures its own memory do not need.
_EXPORTS = {
    **dict.fromkeys(["C_METHODS", "SCIPY_METHODS", "Budget", "Method", "Outcome", "c_method",
                     "default_methods", "jacobian_function", "scipy_method"], "methods"),
    "plot_work_precision": "plots",
    **dict.fromkeys(["Problem", "Reference", "grid", "steps_dividing", "tolerance_sweep"],
                    "problem"),
    **dict.fromkeys(["dop853_extended", "extended_reference", "extended_rhs", "gbs_extended",
                     "linear_reference", "reference_from_methods"], "references"),
    **dict.fromkeys(["STANDARD", "arm_problem", "double_pendulum_problem", "pendulum_problem",
                     "scene_problem", "stiff_chain_problem"], "standard"),
    **dict.fromkeys(["Point", "cost_at_error", "error_measures", "point_at", "run_sweep"],
                    "precision_sweep"),
    **dict.fromkeys(["describe", "markdown_table", "write_tables"], "tables"),
}

__all__ = list(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted({*globals(), *_EXPORTS})
