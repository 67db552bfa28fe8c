"""Every URDF of the ``example-robot-data`` package through modelgen, against Pinocchio.

Input: the package's ``robots`` directory (found through the Python module
``example_robot_data`` or Pinocchio's install prefix).  Output: one
:class:`Agreement` per robot and base (fixed; floating too for the legged
robots, humanoids and flying robots): the size, the generation time, the rhs
operations after CSE and the largest relative errors of A, h - tau(q, 0) and
q'' against Pinocchio's ``crba``, ``nonLinearEffects`` and ``aba`` at random
states.  ``tests/test_urdf_robots.py`` asserts the agreement,
``bench/urdf_robots.py`` writes ``docs/robots.md``.

Pinocchio reads each file with ``mimic=False``, so a mimic joint is a joint of
its own there: the comparison maps modelgen's speeds to Pinocchio's through the
mimic law (v_mimic = multiplier * v), and compares q'' from the reduced
equations (P^T M P) q'' = tau - P^T nle when there are mimic joints.  The
reading options that change bodies (``inertia="balance"``, ``min_mass``,
``min_inertia``) are applied to Pinocchio's own merged bodies by
:func:`adjusted_pinocchio_model` (MuJoCo's rule written out again), so the
reference is independent of modelgen's implementation of them.

>>> sorted(OPTIONS)[:1]
['alex_description/urdf/alex_psyonic_hands.urdf']
"""
from __future__ import annotations

import math
import time
import warnings
from pathlib import Path
from typing import NamedTuple, Optional

import numpy as np

from modelgen.model.urdf import import_urdf, sanitize
from modelgen.sim.load import generate_model, load

__all__ = ["OPTIONS", "FLOATING", "NOT_LOADED", "Agreement", "robots_directory",
           "robot_files", "compare", "adjusted_pinocchio_model"]

#: the reading options each robot needs (the ones its refusal names); others need none
OPTIONS = {
    "hector_description/robots/quadrotor_base.urdf": {"floating_base": True},
    "iris_description/robots/iris_simple.urdf": {"floating_base": True},
    "romeo_description/urdf/romeo.urdf": {"min_mass": 1e-3, "min_inertia": 1e-6},
    "romeo_description/urdf/romeo_laas_small.urdf": {"min_mass": 1e-3, "min_inertia": 1e-6,
                                                     "inertia": "balance"},
    "romeo_description/urdf/romeo_small.urdf": {"inertia": "balance"},
    # its <mimic> tags name joints the file does not have (index_q1 for Left_index_q1);
    # Pinocchio loads it only with mimic=False, which is what compare() builds
    "alex_description/urdf/alex_psyonic_hands.urdf": {"mimic": "ignore"},
}

#: files that are not robots either reader can load, and why
NOT_LOADED = {
    "ur_description/urdf/ur3.urdf": "an empty <robot> (no links, no joints, no name: the "
                                    "xacro output of a file that only defines macros; the "
                                    "robot is ur3_robot.urdf); Pinocchio refuses it too",
}

#: robots also compared with a floating base: legged robots, humanoids, flying robots
#: (the directory names of the package)
FLOATING = ("a1_", "alex_", "alexander_", "anymal_", "b1_", "bolt_", "borinot_",
            "centauro_", "g1_", "go1_", "go2_", "hector_", "hextilt_", "human_", "hyq_",
            "icub_", "iris_", "laikago_", "quadruped_", "romeo_", "simple_humanoid_",
            "solo_", "talos_data/robots/talos_full", "talos_data/robots/talos_reduced")


class Agreement(NamedTuple):
    robot: str               # path relative to the robots directory
    floating: bool
    n: int                   # speeds (degrees of freedom)
    nq: int
    seconds: float           # generation (derive, CSE, emit, compile)
    rhs_ops: int             # operations of the rhs after CSE
    formulation: str
    errors: tuple            # largest relative errors of A, h - tau(q, 0), q''
    options: dict
    warnings: tuple          # what the reading options reported


def robots_directory() -> Optional[Path]:
    """The ``robots`` directory of example-robot-data, or None when it is not installed."""
    try:
        import example_robot_data
        path = Path(example_robot_data.getModelPath("robots/ur_description"))
        if (path / "robots").is_dir():
            return path / "robots"
    except (ImportError, AttributeError, OSError, ValueError):
        pass
    try:
        import pinocchio
    except ImportError:
        return None
    for parent in Path(pinocchio.__file__).resolve().parents:
        share = parent / "share" / "example-robot-data" / "robots"
        if share.is_dir():
            return share
    return None


def robot_files(directory: Path) -> list:
    """Every ``.urdf`` below ``directory``, as sorted relative paths."""
    return sorted(str(p.relative_to(directory)) for p in directory.rglob("*.urdf"))


def floating_too(relative: str) -> bool:
    return relative.startswith(FLOATING)


def adjusted_pinocchio_model(pm, inertia: str = "physical", min_mass: float = 0.0,
                             min_inertia: float = 0.0):
    """Pinocchio's model with MuJoCo's compiler rules applied to each moving body
    (``boundmass``, ``boundinertia`` on the principal moments, then ``balanceinertia``:
    all three moments set to their mean when one exceeds the sum of the others)."""
    import pinocchio as pin
    for jid in range(1, pm.njoints):
        y = pm.inertias[jid]
        mass, lever, moments = y.mass, np.array(y.lever), np.array(y.inertia)
        d, axes = np.linalg.eigh(moments)
        changed = mass < min_mass or np.any(d < min_inertia)
        mass, d = max(mass, min_mass), np.maximum(d, min_inertia)
        if inertia == "balance" and (d[0] + d[1] < d[2]):
            d, changed = np.full(3, d.sum() / 3), True
        if changed:
            pm.inertias[jid] = pin.Inertia(mass, lever, axes @ np.diag(d) @ axes.T)
    return pm


def pinocchio_maps(pm, imp, cm):
    """q -> Pinocchio's q, and P (nv_pin x n) with Pinocchio's v = P v, for the
    Pinocchio model ``pm`` of the URDF that ``imp`` (its import) and ``cm`` come from.
    A free joint's speeds are in its body frame in both (Pinocchio's free flyer)."""
    joints = {j.name: j for j in imp.joints}
    names, speeds = list(cm.coordinates), list(cm.speeds)
    P = np.zeros((pm.nv, cm.n))
    parts = []
    for jid in range(1, pm.njoints):
        jm, name = pm.joints[jid], pm.names[jid]
        info = joints.get(name)
        if info is None or info.type == "floating":       # root_joint, or a floating one
            stem = sanitize(name)
            qn = [names.index(f"{stem}_{s}") for s in ("x", "y", "z", "qx", "qy", "qz", "qw")]
            for k, s in enumerate(("vx", "vy", "vz", "wx", "wy", "wz")):
                P[jm.idx_v + k, speeds.index(f"{stem}_{s}")] = 1.0
            parts.append((jm.idx_q, qn, None, 1.0, 0.0))
            continue
        coordinate, mult, off = (info.coordinate, 1.0, 0.0) if info.mimic is None \
            else info.mimic
        P[jm.idx_v, speeds.index(coordinate + "_dot")] = mult
        parts.append((jm.idx_q, [names.index(coordinate)], jm.nq, mult, off))

    def q_pin(q):
        out = np.zeros(pm.nq)
        for iq, ks, nq, mult, off in parts:
            if nq is None:
                out[iq:iq + 7] = q[ks]
            else:
                angle = mult * q[ks[0]] + off
                out[iq:iq + nq] = [math.cos(angle), math.sin(angle)] if nq == 2 else [angle]
        return out
    return q_pin, P


def _relative(x, ref) -> float:
    return float(np.max(np.abs(x - ref)) / max(np.max(np.abs(ref)), 1e-300))


def compare(directory: Path, relative: str, out_dir: Path, *, floating: bool = False,
            samples: int = 3, seed: int = 20261126) -> Agreement:
    """Generate one robot (timed) and compare it with Pinocchio at ``samples`` states."""
    import pinocchio as pin
    path = directory / relative
    options = dict(OPTIONS.get(relative, {}))
    options["floating_base"] = floating or options.get("floating_base", False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        imp = import_urdf(path, **options)
    t0 = time.perf_counter()
    generated = generate_model(imp.model, out_dir, force=True)
    seconds = time.perf_counter() - t0
    cm = load(imp.model, out_dir)
    pm = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer()) \
        if options["floating_base"] else pin.buildModelFromUrdf(str(path))
    adjusted_pinocchio_model(pm, options.get("inertia", "physical"),
                             options.get("min_mass", 0.0), options.get("min_inertia", 0.0))
    pd = pm.createData()
    q_pin, P = pinocchio_maps(pm, imp, cm)
    rng = np.random.default_rng(seed)
    nu, worst = len(cm.inputs), np.zeros(3)
    for _ in range(samples):
        q = cm.project(rng.uniform(-1.5, 1.5, cm.nq))
        v, u = rng.uniform(-2, 2, cm.n), rng.uniform(-5, 5, nu)
        pq, pv = q_pin(q), P @ v
        m_pin = pin.crba(pm, pd, pq)
        a_ref = P.T @ (np.triu(m_pin) + np.triu(m_pin, 1).T) @ P
        nle = P.T @ pin.nonLinearEffects(pm, pd, pq, pv)
        tau_gravity = cm.generalized_forces(0.0, q, np.zeros(cm.n), np.zeros(nu))
        tau = cm.generalized_forces(0.0, q, v, u) - tau_gravity   # efforts and damping
        if pm.nv == cm.n:
            qdd_ref = P.T @ pin.aba(pm, pd, pq, pv, P @ tau)
        else:           # mimic joints: the reduced equations from Pinocchio's CRBA and RNEA
            qdd_ref = np.linalg.solve(a_ref, tau - nle)
        errors = (_relative(cm.mass_matrix(q), a_ref),
                  _relative(cm.velocity_terms(q, v) - tau_gravity, nle),
                  _relative(cm.rhs(0.0, np.concatenate([q, v]), u)[cm.nq:], qdd_ref))
        worst = np.maximum(worst, errors)
    return Agreement(relative, options["floating_base"], cm.n, cm.nq, seconds,
                     generated.ops["rhs"]["after_cse"], generated.manifest["formulation"],
                     tuple(float(e) for e in worst),
                     {k: v for k, v in options.items() if v and k != "floating_base"},
                     tuple(str(w.message) for w in caught))
