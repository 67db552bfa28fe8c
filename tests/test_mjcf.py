"""MJCF import (modelgen.model.mjcf) against MuJoCo itself, and armature.

MuJoCo compiles each model; contacts, constraints, limits, frictionloss,
actuation, tendon passive forces, fluid forces and gravity compensation are
switched off in MuJoCo (modelgen ignores them, see docs/mjcf.md), and at 3
seeded random states (random unit quaternions) modelgen's

* A against ``T^T M T`` (M: ``mj_fullM`` after ``mj_forward``, armature in;
  T: :func:`velocity_map`, MuJoCo's qvel = T v),
* ``h - tau`` (tau: gravity, joint springs and dampers) against
  ``T^T (qfrc_bias - qfrc_passive + M dT/dt v)``,
* q_ddot, mapped by :func:`qacc_to_mujoco`, against MuJoCo's ``qacc``,

agree to 1e-10 relative (max-norm).  The models are dm_control's suite and
gymnasium's MuJoCo assets; the whole suite is marked slow, dm_control's
cartpole and acrobot are the fast check.
"""
from __future__ import annotations

import glob
import importlib
import os
import time

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MJCF import needs the mujoco package")

import modelgen                                                   # noqa: E402
from modelgen.errors import ModelError                            # noqa: E402
from modelgen.model import Model, parse_model, spec_to_yaml       # noqa: E402
from modelgen.model.mjcf import (import_mjcf_text, import_mjmodel, qacc_to_mujoco,  # noqa: E402
                                 qpos_to_mujoco, qvel_from_mujoco, qvel_to_mujoco,
                                 qpos_from_mujoco, velocity_map)

TOL = 1e-10


# -- the models --------------------------------------------------------------------

#: dm_control suite domains whose model needs arguments: domain -> (function, kwargs)
_DMC_ARGS = {"swimmer": ("get_model_and_assets", {"n_joints": 6}),
             "lqr": ("get_model_and_assets", {"n_bodies": 6, "n_actuators": 2,
                                              "random": np.random.RandomState(0)}),
             "manipulator": ("make_model", {"use_peg": False, "insert": False}),
             "stacker": ("make_model", {"n_boxes": 2}),
             "quadruped": ("make_model", {"floor_size": 10})}
DMC_DOMAINS = ("acrobot", "ball_in_cup", "cartpole", "cheetah", "dog", "finger", "fish",
               "hopper", "humanoid", "humanoid_CMU", "lqr", "manipulator", "pendulum",
               "point_mass", "quadruped", "reacher", "stacker", "swimmer", "walker")


def dmc_model(domain: str):
    """(MjModel, label) of a dm_control suite domain."""
    suite = pytest.importorskip("dm_control.suite", reason="dm-control is not installed")
    mod = importlib.import_module(f"{suite.__name__}.{domain}")
    function, kwargs = _DMC_ARGS.get(domain, ("get_model_and_assets", {}))
    made = getattr(mod, function)(**kwargs)
    xml, assets = made if isinstance(made, tuple) else (made, None)
    if assets is None:
        from dm_control.suite import common
        assets = common.ASSETS
    return mujoco.MjModel.from_xml_string(xml, assets), f"dm_control/{domain}"


def gym_files() -> list:
    """gymnasium's MuJoCo asset files (empty when gymnasium is missing)."""
    try:
        import gymnasium
    except ImportError:
        return []
    folder = os.path.join(os.path.dirname(gymnasium.__file__), "envs", "mujoco", "assets")
    return sorted(glob.glob(os.path.join(folder, "*.xml")))


# -- the comparison ----------------------------------------------------------------



def comparable(mjmodel):
    """MuJoCo model with contacts, constraints, actuation, tendon passive forces,
    fluid forces and gravity compensation off (changed in place)."""
    bits = mujoco.mjtDisableBit
    mjmodel.opt.disableflags |= (bits.mjDSBL_CONTACT | bits.mjDSBL_CONSTRAINT
                                 | bits.mjDSBL_EQUALITY | bits.mjDSBL_LIMIT
                                 | bits.mjDSBL_FRICTIONLOSS | bits.mjDSBL_ACTUATION)
    mjmodel.tendon_stiffness[:] = 0
    mjmodel.tendon_damping[:] = 0
    mjmodel.tendon_armature[:] = 0
    mjmodel.opt.density = 0
    mjmodel.opt.viscosity = 0
    mjmodel.opt.wind[:] = 0
    mjmodel.body_gravcomp[:] = 0
    return mjmodel


def random_state(imp, cm, rng):
    """(q, v): hinge and slide coordinates in [-1, 1], unit quaternions, speeds N(0, 1)."""
    spec = imp.model.spec()
    q = rng.uniform(-1, 1, spec.nq)
    for j in spec.joints:
        k = spec.coordinates.index(j.quaternion[0])
        quat = rng.normal(size=4)
        q[k:k + 4] = quat / np.linalg.norm(quat)
    return q, rng.normal(size=spec.n)


def relative(a, b) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def compare(mjmodel, label: str, formulation: str = "auto", states: int = 3) -> dict:
    """Import, build and compare at seeded random states; returns the figures."""
    imp = import_mjmodel(mjmodel, label + ".xml", frictionloss="ignore")
    mjmodel = comparable(mjmodel)
    t0 = time.perf_counter()
    cm = modelgen.load(imp.model, formulation=formulation)
    seconds = time.perf_counter() - t0
    data = mujoco.MjData(mjmodel)
    rng = np.random.default_rng(1)
    worst = {"A": 0.0, "h - tau": 0.0, "qdd": 0.0}
    for _ in range(states):
        q, v = random_state(imp, cm, rng)
        data.qpos[:] = qpos_to_mujoco(imp, q)
        data.qvel[:] = qvel_to_mujoco(imp, q, v)
        data.ctrl[:] = 0
        mujoco.mj_forward(mjmodel, data)
        M = np.zeros((mjmodel.nv, mjmodel.nv))
        mujoco.mj_fullM(mjmodel, data, M)
        T = velocity_map(imp, q)
        x = np.concatenate([q, v])
        A = cm.mass_matrix(q)
        bias = cm.velocity_terms(q, v) - cm.generalized_forces(0.0, q, v)
        rate = qacc_to_mujoco(imp, q, v, np.zeros(len(v)))
        expected = T.T @ (data.qfrc_bias - data.qfrc_passive + M @ rate)
        qdd = cm.rhs(0.0, x)[len(q):]
        worst["A"] = max(worst["A"], relative(A, T.T @ M @ T))
        worst["h - tau"] = max(worst["h - tau"], relative(bias, expected))
        worst["qdd"] = max(worst["qdd"], relative(qacc_to_mujoco(imp, q, v, qdd), data.qacc))
    return {"dof": mjmodel.nv, "seconds": seconds, "worst": worst, "notes": imp.notes,
            "ops": cm.manifest.get("ops", {}) if hasattr(cm, "manifest") else {}}


def check(mjmodel, label, formulation="auto"):
    result = compare(mjmodel, label, formulation)
    assert max(result["worst"].values()) <= TOL, (label, result["worst"])
    return result


# -- fast checks -------------------------------------------------------------------

@pytest.mark.parametrize("formulation", ["aba", "crba"])
def test_cartpole_matches_mujoco(formulation):
    pytest.importorskip("dm_control", reason="dm-control is not installed")
    check(*dmc_model("cartpole"), formulation)


def test_acrobot_matches_mujoco():
    pytest.importorskip("dm_control", reason="dm-control is not installed")
    check(*dmc_model("acrobot"))


# -- the whole suites (slow) -----------------------------------------------------

def suite_models():
    """(label, thunk giving the MjModel) of every model of both suites."""
    out = []
    try:
        importlib.import_module("dm_control.suite")
        out += [(f"dm_control/{d}", lambda d=d: dmc_model(d)[0]) for d in DMC_DOMAINS]
    except ImportError:
        pass
    out += [(f"gymnasium/{os.path.basename(f)[:-4]}",
             lambda f=f: mujoco.MjModel.from_xml_path(f)) for f in gym_files()]
    return out


#: models refused for a real reason: label -> the reason (the ModelError must say so)
REFUSED = {}


@pytest.mark.slow
@pytest.mark.parametrize("label, make", suite_models() or [("none", None)],
                         ids=lambda x: x if isinstance(x, str) else "")
def test_suite_model_matches_mujoco(label, make):
    if make is None:
        pytest.skip("neither dm-control nor gymnasium is installed")
    if label in REFUSED:
        with pytest.raises(ModelError, match=REFUSED[label]):
            import_mjmodel(make(), label + ".xml")
        return
    check(make(), label)
