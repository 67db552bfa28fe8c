"""The library part of the benchmarks: work-precision problems, sweeps, references, plots.

One module per job (see ``modelgen/bench/README.md``): ``problem`` (the data
of a problem and its reference), ``methods`` (the C integrators and
solve_ivp behind one call), ``references`` (closed forms, two-method and
extended-precision references), ``precision_sweep`` (the runner, errors, costs),
``tables``, ``plots``, and ``standard`` (the standard problems, whose scenes
ship in ``problems/``).  The names the CLI and ``bench/work_precision.py``
use are re-exported here.

>>> from modelgen import bench
>>> bench.tolerance_sweep(1e-2, 1e-4, per_decade=1)
(0.01, 0.001, 0.0001)
"""
from __future__ import annotations

from modelgen.bench.methods import (C_METHODS, SCIPY_METHODS, Budget, Method, Outcome,
                                    c_method, default_methods, jacobian_function,
                                    scipy_method)
from modelgen.bench.plots import plot_work_precision
from modelgen.bench.problem import (Problem, Reference, grid, steps_dividing,
                                    tolerance_sweep)
from modelgen.bench.references import (dop853_extended, extended_reference, extended_rhs,
                                       gbs_extended, linear_reference,
                                       reference_from_methods)
from modelgen.bench.standard import (STANDARD, arm_problem, double_pendulum_problem,
                                     pendulum_problem, scene_problem, stiff_chain_problem)
from modelgen.bench.precision_sweep import (Point, cost_at_error, error_measures, point_at,
                                            run_sweep)
from modelgen.bench.tables import describe, markdown_table, write_tables

__all__ = ["C_METHODS", "SCIPY_METHODS", "Budget", "Method", "Outcome", "c_method",
           "default_methods", "jacobian_function", "scipy_method", "plot_work_precision",
           "Problem", "Reference", "grid", "steps_dividing", "tolerance_sweep",
           "dop853_extended", "extended_reference", "extended_rhs", "gbs_extended",
           "linear_reference", "reference_from_methods", "STANDARD", "scene_problem",
           "pendulum_problem", "double_pendulum_problem", "arm_problem", "stiff_chain_problem",
           "Point", "cost_at_error", "error_measures", "point_at", "run_sweep", "describe",
           "markdown_table", "write_tables"]
