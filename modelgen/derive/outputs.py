"""Outputs stage: the quantities a scene records, as expressions of the state.

A scene asks for outputs by kind (see :data:`modelgen.model.spec.OUTPUT_KINDS`);
this stage turns each into expressions over the same named intermediates as
the equations, so they share CSE with nothing else and cost nothing when no
scene asks for them.  Each output has named columns, e.g. ``tip.x``.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy

from modelgen.derive.constrained_linearize import multipliers
from modelgen.derive.constraints import constraint_rows
from modelgen.derive.dynamics import Equations
from modelgen.derive.graph import Graph, GraphBuilder
from modelgen.derive.spatial import sub
from modelgen.derive.kinematics import Kinematics

AXES = ("x", "y", "z")


@dataclass(frozen=True)
class OutputColumns:
    """Outputs ready for the C routine: columns and their expressions."""
    graph: Graph
    names: tuple            # output names, in order
    columns: tuple          # per output: tuple of column names
    exprs: tuple            # flat, one per column
    #: per column, the index of the constraint force it records (-1: none); the
    #: routine then reads the multipliers ``lam`` the rhs solves for
    multipliers: tuple = ()

    @property
    def reads_multipliers(self) -> bool:
        return any(k >= 0 for k in self.multipliers)


def _transpose_times(R, v):
    """R^T v: components in the base whose matrix is R."""
    return tuple(sympy.Add(*[R[i][j] * v[i] for i in range(3)]) for j in range(3))


def derive_outputs(kin: Kinematics, eqs: Equations, outputs) -> OutputColumns:
    """Expressions for every requested output (``outputs``: OutputSpec tuple).

    >>> cols = derive_outputs(kin, eqs, scene.outputs)        # doctest: +SKIP
    >>> cols.columns[0]                                        # doctest: +SKIP
    ('tip.x', 'tip.y', 'tip.z')
    """
    builder = GraphBuilder(eqs.graph)
    names, columns, exprs, lam_of = [], [], [], []
    rows = constraint_rows(kin.spec) if kin.spec.constraints else ()
    lam = multipliers(len(rows))
    parts = dict(eqs.tau_parts)
    body_index = {b: i for i, b in enumerate(eqs.bodies)}
    for out in outputs:
        a = dict(out.args)
        if out.kind == "position":
            R = kin.bases[a["base"]].R
            d = sub(kin.points[a["point"]].r, kin.points[a["from"]].r)
            values, cols = _transpose_times(R, d), [f"{out.name}.{c}" for c in AXES]
        elif out.kind == "velocity":
            R = kin.bases[a["base"]].R
            values = _transpose_times(R, kin.points[a["point"]].v)
            cols = [f"{out.name}.{c}" for c in AXES]
        elif out.kind == "orientation":
            # change of basis: v_relative_to = M v_base, M = R_rel^T R_base
            R1, R2 = kin.bases[a["relative_to"]].R, kin.bases[a["base"]].R
            values = [sympy.Add(*[R1[k][i] * R2[k][j] for k in range(3)])
                      for i in range(3) for j in range(3)]
            cols = [f"{out.name}[{i},{j}]" for i in range(3) for j in range(3)]
        elif out.kind == "angular_velocity":
            w = sub(kin.bases[a["base"]].omega, kin.bases[a["relative_to"]].omega)
            values = _transpose_times(kin.bases[a["components"]].R, w)
            cols = [f"{out.name}.{c}" for c in AXES]
        elif out.kind == "energy":
            which = a["which"]
            values = [{"kinetic": eqs.kinetic, "potential": eqs.potential,
                       "total": eqs.kinetic + eqs.potential}[which]]
            cols = [out.name]
        elif out.kind == "generalized_force":
            values = list(parts[a["effect"]])
            cols = [f"{out.name}.{c}" for c in kin.spec.dof_names]
        elif out.kind == "power":
            # the power of the effect's forces: its generalized force . q_dot
            values = [sympy.Add(*[f * v for f, v in zip(parts[a["effect"]], eqs.qd, strict=True)])]
            cols = [out.name]
        elif out.kind == "pose":
            values = list(eqs.poses[body_index[a["body"]]])
            cols = [f"{out.name}[{i},{j}]" for i in range(4) for j in range(4)]
        elif out.kind == "constraint_force":
            # the multipliers of the constraint's rows, by axis (G^T lam is the
            # generalized force the constraints add: docs/constraints.md)
            mine = sorted((axis, k) for k, (name, axis) in enumerate(rows)
                          if name == a["constraint"])
            values = [lam[k] for _, k in mine]
            cols = [f"{out.name}.{AXES[axis - 1]}" if axis else out.name for axis, _ in mine]
            lam_of.extend(k for _, k in mine)
            names.append(out.name)
            columns.append(tuple(cols))
            exprs.extend(values)
            continue
        else:   # pragma: no cover - the scene loader only produces the kinds above
            raise ValueError(f"unknown output kind {out.kind!r}")
        names.append(out.name)
        columns.append(tuple(cols))
        exprs.extend(builder.name(v) for v in values)
        lam_of.extend(-1 for _ in values)
    return OutputColumns(builder.freeze(), tuple(names), tuple(columns), tuple(exprs),
                         tuple(lam_of))
