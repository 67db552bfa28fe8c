"""PyDy's side of the generation benchmark: the spatial chain in sympy.physics.mechanics,
its equations by Kane's method and compiled by PyDy's Cython backend.

The model is :func:`modelgen.model.chains.spatial_chain` exactly (same bases,
points, masses, inertias, gravity), so the two generators do the same job.
Run as a script, it generates one chain and prints the seconds of each step, then
on a line of its own :data:`XDOT_MARK` and the JSON of the generated rhs at
:data:`CHECK_STATE` with :func:`chain_constants` (the benchmark
``bench/load_time.py`` runs it in a fresh process and compares that with
modelgen's rhs of the same chain)::

    python -m modelgen.bench.pydy_models 6 OUT_DIR

It needs ``pydy`` and ``cython`` (not dependencies of modelgen).
"""
from __future__ import annotations

import json
import sys
import time

XDOT_MARK = "@@pydy-xdot@@ "
CHECK_STATE = 0.1       # every q and u of the state the rhs is evaluated at


def chain_constants(n: int) -> list:
    """m1..mn, l1..ln, r, g: the defaults of ``spatial_chain(n)``'s parameters."""
    return [1.0] * n + [0.5] * n + [0.02, 9.81]


def chain_kane(n: int):
    """(KanesMethod, q, u, constants) of the n-link spatial chain, equations formed."""
    import sympy as sm
    import sympy.physics.mechanics as me
    q = me.dynamicsymbols(f"q1:{n + 1}")
    u = me.dynamicsymbols(f"u1:{n + 1}")
    m = sm.symbols(f"m1:{n + 1}")
    lengths = sm.symbols(f"l1:{n + 1}")
    r, g = sm.symbols("r g")
    frame_e = me.ReferenceFrame("E")
    origin = me.Point("O")
    origin.set_vel(frame_e, 0)
    previous_frame, previous_point = frame_e, origin
    bodies, loads = [], []
    for i in range(n):
        axis = previous_frame.z if i % 2 == 0 else previous_frame.y   # joint i+1: z if odd
        frame = previous_frame.orientnew(f"B{i + 1}", "Axis", (q[i], axis))
        frame.set_ang_vel(previous_frame, u[i] * axis)
        centre = previous_point.locatenew(f"G{i + 1}", lengths[i] / 2 * frame.x)
        centre.v2pt_theory(previous_point, frame_e, frame)
        joint = previous_point.locatenew(f"P{i + 1}", lengths[i] * frame.x)
        joint.v2pt_theory(previous_point, frame_e, frame)
        transverse = m[i] * lengths[i] ** 2 / 12 + m[i] * r ** 2 / 4
        inertia = me.inertia(frame, m[i] * r ** 2 / 2, transverse, transverse)
        bodies.append(me.RigidBody(f"rod{i + 1}", centre, frame, m[i], (inertia, centre)))
        loads.append((centre, -m[i] * g * frame_e.z))
        previous_frame, previous_point = frame, joint
    kd = [qi.diff() - ui for qi, ui in zip(q, u)]
    kane = me.KanesMethod(frame_e, q_ind=q, u_ind=u, kd_eqs=kd)
    kane.kanes_equations(bodies, loads)
    return kane, q, u, list(m) + list(lengths) + [r, g]


def generate_chain(n: int, out_dir: str) -> dict:
    """Form the chain's equations and compile them with PyDy's Cython backend into
    ``out_dir``; the seconds of each step and the rhs at :data:`CHECK_STATE`
    (``xdot``: q', u')."""
    t0 = time.perf_counter()
    from pydy.codegen.ode_function_generators import generate_ode_function
    t1 = time.perf_counter()
    kane, q, u, constants = chain_kane(n)
    t2 = time.perf_counter()
    rhs = generate_ode_function(kane.forcing_full, q, u, constants,
                                mass_matrix=kane.mass_matrix_full, generator="cython",
                                tmp_dir=out_dir)
    t3 = time.perf_counter()
    import numpy as np
    xdot = rhs(np.full(2 * n, CHECK_STATE), 0.0, np.array(chain_constants(n)))
    if not np.all(np.isfinite(xdot)):
        raise RuntimeError("PyDy's rhs is not finite")
    return {"import": t1 - t0, "kane": t2 - t1, "codegen+compile": t3 - t2,
            "xdot": [float(v) for v in xdot]}


if __name__ == "__main__":
    start = time.perf_counter()
    figures = generate_chain(int(sys.argv[1]), sys.argv[2])
    xdot = figures.pop("xdot")
    print(" ".join(f"{k}={v:.3f}" for k, v in figures.items()),
          f"total={time.perf_counter() - start:.3f}")
    print(XDOT_MARK + json.dumps(xdot))
