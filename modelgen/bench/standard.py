"""The standard work-precision problems, and a problem from any scene.

The standard set's scenes and models ship with the package, in
``modelgen/bench/problems/`` (scenes in ``problems/scenes/``, each naming its
model as ``../<model>.yaml``), so they work from an installed wheel as well
as from a source checkout.  :data:`STANDARD` maps a problem's name to the
function that builds it; :func:`scene_problem` makes a problem of any scene
file.

>>> sorted(STANDARD)
['arm7', 'double_pendulum', 'pendulum', 'stiff_chain']
>>> sorted(path.name for path in SCENES.glob("*.yaml"))[:2]
['arm7_damped.yaml', 'dp_free.yaml']
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import mpmath
import numpy as np
from scipy.special import ellipj, ellipk

from modelgen.bench.problem import (Problem, Reference, grid, steps_dividing,
                                    tolerance_sweep)
from modelgen.bench.references import (extended_reference, linear_reference,
                                       reference_from_methods)
from modelgen.codegen.pipeline import default_output
from modelgen.errors import SimulationError
from modelgen.model.scene import load_scene
from modelgen.sim.load import load

#: the standard set's models (package data)
PROBLEMS = Path(__file__).resolve().parent / "problems"
#: the standard set's scenes (package data)
SCENES = PROBLEMS / "scenes"
#: models with at most this many coordinates are built with the symbolic Jacobian
JACOBIAN_UP_TO = 12


def _build(spec, build_dir):
    """The scene's reduced model, compiled (with the symbolic Jacobian when small)."""
    if build_dir is None:
        build_dir = default_output("workprecision") / spec.name
    return load(spec.model, build_dir, jacobian=spec.model.n <= JACOBIAN_UP_TO)


def _scene_model(scene_file: str, build_root):
    """(SceneSpec, CompiledModel) of one of the standard set's scenes."""
    spec = load_scene(SCENES / scene_file)
    return spec, _build(spec, None if build_root is None else Path(build_root) / spec.name)


def _constant_inputs(spec):
    if not spec.inputs:
        return None
    sampled = [sig.name for sig in spec.inputs if sig.constant is None]
    if sampled:
        raise SimulationError(f"scene {spec.name}: work-precision diagrams need constant "
                              f"inputs; {', '.join(sampled)} are sampled in time")
    return {sig.name: sig.constant for sig in spec.inputs}


def pendulum_problem(build_root=None, periods: int = 4, quick: bool = False) -> Problem:
    """Simple pendulum released from rest at 90 degrees (L = 1, g = 9.81), over
    ``periods`` periods T = 4 sqrt(L/g) K(sin^2(45 deg)) = 2.367841947576237 s.

    Closed-form reference: theta(t) = 2 asin(k sn(K - w t | k^2)) with mpmath
    (30 digits) on the grid; after whole periods it is exactly the release
    angle.  scipy's ``ellipj`` gives the same to ~1e-14 (checked).
    """
    spec, cm = _scene_model("simple_pendulum_swing.yaml", build_root)
    theta0, omega0 = spec.initial
    if omega0 != 0:
        raise SimulationError("pendulum_problem: the scene must release from rest")
    L, g = cm.parameters["L"], cm.parameters["g"]
    k = math.sin(theta0 / 2)
    period = 4 * math.sqrt(L / g) * float(ellipk(k * k))
    t = grid(0.0, periods * period)
    with mpmath.workdps(30):
        mk = mpmath.sin(mpmath.mpf(theta0) / 2)
        mK, w = mpmath.ellipk(mk ** 2), mpmath.sqrt(mpmath.mpf(g) / mpmath.mpf(L))
        q = np.array([float(2 * mpmath.asin(mk * mpmath.ellipfun("sn", mK - w * mpmath.mpf(ti),
                                                                   m=mk ** 2))) for ti in t])
    q[-1] = theta0                          # whole periods: back at the release angle
    sn = ellipj(float(ellipk(k * k)) - math.sqrt(g / L) * t, k * k)[0]
    check = float(np.max(np.abs(2 * np.arcsin(k * sn) - q)))
    rounding = 4 * np.finfo(float).eps * float(np.max(np.abs(q)))
    ref = Reference(t, q[:, None], f"closed form θ(t) = 2 asin(k sn(K − ωt | k²)) in mpmath "
                    f"(scipy ellipj agrees to {check:.0e}); θ(T) = θ0 after whole periods",
                    rounding, rounding)
    tols = tolerance_sweep(1e-3, 1e-12, 1 if quick else 2)
    spacing = t[1] - t[0]
    steps = {"*": steps_dividing(spacing, 1, 1000, 2 if quick else 4)}
    return Problem("pendulum", f"simple pendulum released from horizontal, {periods} periods",
                   cm, np.array(spec.initial), (0.0, float(t[-1])), t, ref, tolerances=tols,
                   steps=steps,
                   notes=(f"Period T = {period!r} s (L = {L:g} m, g = {g:g} m/s²). The final "
                          f"time is a turning point (θ' = 0), so a phase error δt shows in "
                          f"θ(T) only as θ''δt²/2; the dense L2 error sees it at first "
                          f"order.",))


def double_pendulum_problem(build_root=None, t_end: float = 10.0, quick: bool = False,
                            reference: bool = True) -> Problem:
    """The free double pendulum (scene dp_free: q1 = 1, q2 = 0.5 from rest) over 10 s.

    It is chaotic here (the outer rod turns over; errors grow about e^t), so two
    double-precision methods at 1e-13 disagree by ~1e-10 at 10 s; the reference
    is made in long double instead (:func:`extended_reference`).
    """
    spec, cm = _scene_model("dp_free.yaml", build_root)
    t = grid(0.0, t_end)
    tols = tolerance_sweep(1e-4, 1e-13, 1 if quick else 2)
    steps = {"*": steps_dividing(t[1] - t[0], 2, 2000, 2 if quick else 4)}
    problem = Problem("double_pendulum", f"double pendulum (dp_free), {t_end:g} s", cm,
                      np.array(spec.initial), (0.0, t_end), t, None,
                      u=_constant_inputs(spec), tolerances=tols, steps=steps)
    if reference:
        problem = replace(problem, reference=extended_reference(spec.model, problem))
    return problem


def arm_problem(build_root=None, t_end: float = 5.0, quick: bool = False) -> Problem:
    """The 7-joint arm falling under gravity with joint damping (scene arm7_damped), 5 s.

    Reference: two high-order methods at 1e-14 (:func:`reference_from_methods`).
    """
    spec, cm = _scene_model("arm7_damped.yaml", build_root)
    t = grid(0.0, t_end)
    tols = tolerance_sweep(1e-3, 1e-10, 1 if quick else 2)
    steps = {"*": steps_dividing(t[1] - t[0], 1, 1000, 2 if quick else 4)}
    problem = Problem("arm7", f"7-joint arm with joint damping (arm7_damped), {t_end:g} s", cm,
                      np.array(spec.initial), (0.0, t_end), t, None, u=_constant_inputs(spec),
                      tolerances=tols, steps=steps)
    return replace(problem, reference=reference_from_methods(problem))


def stiff_chain_problem(build_root=None, quick: bool = False) -> Problem:
    """The stiff spring chain (scene spring_chain_stiff, 2 s): masses 1 and 2 joined
    by a spring 1e6 times stiffer than the others with a stiff damper beside it,
    so the Jacobian's eigenvalues run from -2e7 to -0.03 1/s.

    The system is linear, so the reference is its matrix exponential
    (:func:`linear_reference`).  RK4 is swept around its stability limit
    (h ~ 1.4e-7 s); the implicit fixed-step methods from the grid spacing.
    """
    spec, cm = _scene_model("spring_chain_stiff.yaml", build_root)
    t = grid(spec.t_start, spec.t_end)
    x0 = np.array(spec.initial)
    ref = linear_reference(cm, x0, t)
    eig = np.linalg.eigvals(cm.jac(0.0, x0))
    lo, hi = np.min(np.abs(eig)), np.max(np.abs(eig))
    tols = tolerance_sweep(1e-3, 1e-10, 1 if quick else 2)
    spacing = t[1] - t[0]
    per = 2 if quick else 4
    steps = {"rk4": steps_dividing(spacing, 10 ** 4.5, 10 ** 5, per),
             "*": steps_dividing(spacing, 1, 1000, per)}
    return Problem("stiff_chain", f"stiff spring chain (spring_chain_stiff), {spec.t_end:g} s",
                   cm, x0, (spec.t_start, spec.t_end), t, ref, tolerances=tols, steps=steps,
                   notes=(f"Eigenvalues of the Jacobian: |λ| from {lo:.3g} to {hi:.3g} 1/s "
                          f"(ratio {hi / lo:.1e}); real parts from "
                          f"{-np.max(np.abs(eig.real)):.3g} to "
                          f"{-np.min(np.abs(eig.real)):.3g} 1/s.",))


#: the standard set, by name
STANDARD = {"pendulum": pendulum_problem, "double_pendulum": double_pendulum_problem,
            "arm7": arm_problem, "stiff_chain": stiff_chain_problem}


def scene_problem(scene_path, build_dir=None, *, quick: bool = False,
                  tolerance: float = 1e-14) -> Problem:
    """A work-precision problem from any scene: its initial state and time span,
    constant inputs, a 201-point grid, and a reference by two high-order methods
    (:func:`reference_from_methods`).  Fixed steps go from 10x to 1/10 of the
    scene's integrator step.
    """
    spec = load_scene(scene_path)
    cm = _build(spec, build_dir)
    t = grid(spec.t_start, spec.t_end)
    spacing = t[1] - t[0]
    per_interval = spacing / spec.step
    steps = {"*": steps_dividing(spacing, max(per_interval / 10, 1), max(per_interval * 10, 10),
                                 2 if quick else 4)}
    tols = tolerance_sweep(1e-3, 1e-10, 1 if quick else 2)
    problem = Problem(spec.name, f"scene {spec.name}", cm, np.array(spec.initial),
                      (spec.t_start, spec.t_end), t, None, u=_constant_inputs(spec),
                      tolerances=tols, steps=steps)
    return replace(problem, reference=reference_from_methods(problem, tolerance=tolerance))
