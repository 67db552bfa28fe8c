"""Inertia tensors of model files: read, checked symmetric, checked physical.

The checks run on numbers (the default parameters and seeded scalings of
them), never on expanded expressions, and scale by the largest entry first so
that no square overflows.
"""
from __future__ import annotations

import math

import sympy

from modelgen.model.expr import format_expression
from modelgen.model.messages import as_list, describe

#: the symmetry of an inertia matrix is checked numerically, at the default parameters
#: and at SYMMETRY_SAMPLES - 1 seeded random scalings of them, to this relative tolerance
#: of the matrix's largest entry (a tensor from R diag(d) R^T differs by ulps across the
#: diagonal; an exact comparison refused most real tensors, a symbolic one could hang)
SYMMETRY_SAMPLES = 3
SYMMETRY_RTOL = 1e-9


def read_inertia(builder, value, key: str, body: str) -> tuple:
    """The inertia tensor of ``body`` from a model file's value: None (a particle),
    three principal moments or a 3x3 matrix, symmetric to rounding (checked
    numerically, never by expansion)."""
    zero = sympy.Integer(0)
    if value is None:
        return ((zero,) * 3,) * 3
    shape = "write [Ixx, Iyy, Izz] (principal moments) or a 3x3 matrix [[Ixx, Ixy, Ixz], " \
            "[Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]]"
    rows = as_list(value)
    if not isinstance(rows, list) or len(rows) != 3:
        raise builder.error("expected 3 principal moments or a 3x3 matrix but got "
                         f"{describe(value)}", key, shape)
    rows = [as_list(row) for row in rows]
    if not any(isinstance(row, list) for row in rows):
        diagonal = [builder.expression(item, f"{key}[{i}]", "constant")
                    for i, item in enumerate(rows)]
        return tuple(tuple(diagonal[i] if i == j else zero for j in range(3))
                     for i in range(3))
    for i, row in enumerate(rows):
        if not isinstance(row, list) or len(row) != 3:
            raise builder.error(f"row {i + 1} of the 3x3 inertia matrix is "
                             f"{describe(row)}, not a list of 3 items", key, shape)
    matrix = [[builder.expression(item, f"{key}[{i}][{j}]", "constant")
               for j, item in enumerate(row)] for i, row in enumerate(rows)]
    # sampled once a pair differs (a symmetric matrix, the usual one, needs none),
    # from the matrix as written
    written, samples = [row[:] for row in matrix], []
    for i in range(3):
        for j in range(i + 1, 3):
            upper, lower = matrix[i][j], matrix[j][i]
            if upper == lower:
                continue
            samples = samples or [sample_values(builder, written, k)
                                  for k in range(SYMMETRY_SAMPLES)]
            for values in samples:
                if values is None:
                    continue
                scale = max(abs(v) for row in values for v in row) or 1.0
                if not abs(values[i][j] - values[j][i]) <= SYMMETRY_RTOL * scale:
                    raise builder.error(
                        f"inertia of body '{body}' is not symmetric: entry [{i}][{j}] is "
                        f"{format_expression(upper)} but entry [{j}][{i}] is "
                        f"{format_expression(lower)}", key,
                        f"make entries [{i}][{j}] and [{j}][{i}] equal")
            # equal to rounding (a tensor computed as R diag(d) R^T): keep their mean
            matrix[i][j] = matrix[j][i] = (
                (upper + lower) / 2 if upper.is_Number and lower.is_Number else upper)
    return tuple(tuple(row) for row in matrix)

def sample_values(builder, matrix, k: int):
    """The 3x3 ``matrix`` evaluated numerically (never expanded): at the defaults for
    ``k = 0``, else with every parameter scaled by a seeded factor in [0.5, 2].
    None when it is not real there."""
    if k == 0:
        values = builder.defaults
    else:
        import numpy as np      # here: a model of principal moments never samples
        rng = np.random.default_rng(k)
        values = {s: sympy.Float(float(v) * rng.uniform(0.5, 2.0))
                  for s, v in builder.defaults.items()}
    out = []
    for row in matrix:
        try:
            out.append([float(item.xreplace(values)) for item in row])
        except (TypeError, ValueError, OverflowError):
            return None
    return out if all(math.isfinite(v) for row in out for v in row) else None

def check_physical_inertia(builder, body: str, inertia: tuple, key: str) -> None:
    """Refuse an inertia no rigid body has at the default parameters."""
    values = [[builder.at_defaults(item) for item in row] for row in inertia]
    if any(v is None for row in values for v in row):
        raise builder.error(f"inertia of body '{body}' is not real with the default "
                         "parameters", key, "check the inertia expressions")
    # scaled by the largest entry first, so that squares inside the eigen solver
    # cannot overflow (entries near 1e308) and the test is the same at any scale
    d, scale = _scaled_eigenvalues(values)
    moments = [v * scale for v in d]
    tol = 1e-9 * max(1.0 / scale, max(abs(v) for v in d))
    shown = "[" + ", ".join(f"{m:.6g}" for m in moments) + "]"
    if d[0] < -tol:
        raise builder.error(f"inertia of body '{body}' has a negative principal moment "
                         f"with the default parameters: {shown}", key,
                         "give a positive semi-definite inertia tensor about G")
    if d[0] + d[1] < d[2] - tol:
        raise builder.error(f"inertia of body '{body}' violates the triangle inequality "
                         f"with the default parameters: principal moments {shown}, "
                         f"{moments[0]:.6g} + {moments[1]:.6g} < {moments[2]:.6g}", key,
                         "no rigid body has these moments; each principal moment must "
                         "be at most the sum of the other two")


def _scaled_eigenvalues(values: list) -> tuple:
    """``(eigenvalues of values / scale in ascending order, scale)``, ``scale`` the
    largest absolute entry of the 3x3 ``values`` (1 if all are zero).

    A diagonal matrix (principal moments, the usual inertia) is its own answer:
    its sorted diagonal, which is what LAPACK's symmetric solver returns for it
    to the last bit, without importing numpy, which a model read to be generated
    would otherwise import for this check alone; any other matrix goes to
    ``numpy.linalg.eigvalsh``."""
    m = [[float(v) for v in row] for row in values]
    if all(m[i][j] == 0 for i in range(3) for j in range(3) if i != j) \
            and all(math.isfinite(m[i][i]) for i in range(3)):
        scale = max(abs(m[i][i]) for i in range(3)) or 1.0
        return sorted(m[i][i] / scale for i in range(3)), scale
    import numpy as np          # here: see above
    matrix = np.array(values, dtype=float)
    scale = float(np.max(np.abs(matrix))) or 1.0
    return [float(v) for v in np.linalg.eigvalsh(matrix / scale)], scale
