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

agree to 1e-12 relative (max-norm).  The models are dm_control's suite and
gymnasium's MuJoCo assets; the whole suite is marked slow, dm_control's
cartpole and acrobot are the fast check.

A model with equality constraints is compared twice: its position-constraint
residuals f(q) against MuJoCo's own violations (the ``efc_pos`` rows of type
``mjCNSTR_EQUALITY`` after ``mj_forward``, equalities on) at random
configurations that satisfy nothing, to 1e-12; and A and ``h - tau`` as above
with the equalities off (its q_ddot is the constrained one, which MuJoCo's soft
constraints do not reproduce, so it is not compared).
"""
from __future__ import annotations

import glob
import importlib
import os
import time

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MJCF import needs the mujoco package")

import modelgen
from modelgen.errors import ModelError
from modelgen.model import parse_model
from modelgen.model.mjcf import (
    import_mjcf_text,
    import_mjmodel,
    mjcf_to_yaml,
    qacc_to_mujoco,
    qpos_from_mujoco,
    qpos_to_mujoco,
    qvel_from_mujoco,
    qvel_to_mujoco,
    velocity_map,
)

#: relative (max-norm, over max |MuJoCo's value|) for A, h - tau and q_ddot; measured
#: worst 1.2e-14 in the fast checks (the synthetic model by crba) and 8.4e-14 over the
#: whole suites (dm_control's humanoid_CMU q_ddot; docs/mjcf.md's table)
TOL = 1e-12


@pytest.fixture(autouse=True)
def _mujoco_log_outside_the_checkout(tmp_path, monkeypatch):
    """MuJoCo writes its warnings (a NaN in a file...) to ./MUJOCO_LOG.TXT."""
    monkeypatch.chdir(tmp_path)


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


def equality_violations(mjmodel, imp, cm, rng, states: int = 5) -> float:
    """Worst |f(q) - MuJoCo's equality violation| over ``states`` random
    configurations, rows matched by ``imp.equality_rows``; MuJoCo's rows that the
    import left out (identically zero) must be zero."""
    data = mujoco.MjData(mjmodel)
    worst = 0.0
    for _ in range(states):
        q, _ = random_state(imp, cm, rng)
        data.qpos[:] = qpos_to_mujoco(imp, q)
        mujoco.mj_forward(mjmodel, data)
        rows = {}
        for r in np.flatnonzero(data.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY):
            rows.setdefault(int(data.efc_id[r]), []).append(float(data.efc_pos[r]))
        expected = np.array([rows[e][k] for e, k in imp.equality_rows])
        left_out = [v for e, values in rows.items() for k, v in enumerate(values)
                    if (e, k) not in imp.equality_rows]
        f = cm.constraint_residuals(q)
        assert len(f) == len(expected)
        worst = max(worst, float(np.max(np.abs(f - expected), initial=0.0)),
                    float(np.max(np.abs(left_out), initial=0.0)))
    return worst


def compare(mjmodel, label: str, formulation: str = "auto", states: int = 3) -> dict:
    """Import, build and compare at seeded random states; returns the figures."""
    imp = import_mjmodel(mjmodel, label + ".xml", frictionloss="ignore")
    generated = modelgen.generate_model(imp.model, formulation=formulation)
    cm = modelgen.load(imp.model, formulation=formulation)     # the same build, cached
    rng = np.random.default_rng(1)
    constrained = bool(imp.equality_rows)
    worst = {"A": 0.0, "h - tau": 0.0}
    if constrained:
        worst["f"] = equality_violations(mjmodel, imp, cm, rng)
    else:
        worst["qdd"] = 0.0
    mjmodel = comparable(mjmodel)
    data = mujoco.MjData(mjmodel)
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
        worst["A"] = max(worst["A"], relative(A, T.T @ M @ T))
        worst["h - tau"] = max(worst["h - tau"], relative(bias, expected))
        if not constrained:
            qdd = cm.rhs(0.0, x)[len(q):]
            worst["qdd"] = max(worst["qdd"], relative(qacc_to_mujoco(imp, q, v, qdd),
                                                      data.qacc))
    return {"dof": mjmodel.nv, "seconds": sum(generated.seconds.values()), "worst": worst,
            "notes": imp.notes, "ops": generated.ops}


#: f(q) against MuJoCo's equality violations (absolute: the values are O(1))
EQUALITY_TOL = 1e-12


def check(mjmodel, label, formulation="auto"):
    result = compare(mjmodel, label, formulation)
    worst = dict(result["worst"])
    assert worst.pop("f", 0.0) <= EQUALITY_TOL, (label, result["worst"])
    assert max(worst.values()) <= TOL, (label, result["worst"])
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

#: gymnasium-robotics' environment models (the other files there are their includes)
ROBOTICS_FILES = ("adroit_hand/adroit_door.xml", "adroit_hand/adroit_hammer.xml",
                  "adroit_hand/adroit_pen.xml", "adroit_hand/adroit_relocate.xml",
                  "fetch/pick_and_place.xml", "fetch/push.xml", "fetch/reach.xml",
                  "fetch/slide.xml", "hand/manipulate_block.xml", "hand/manipulate_egg.xml",
                  "hand/manipulate_pen.xml", "hand/reach.xml",
                  "kitchen_franka/kitchen_assets/kitchen_env_model.xml", "point/point.xml")


def robotics_files() -> list:
    """(label, path) of gymnasium-robotics' models (empty when it is missing)."""
    try:
        import gymnasium_robotics
    except ImportError:
        return []
    folder = os.path.join(os.path.dirname(gymnasium_robotics.__file__), "envs", "assets")
    return [(f"gymnasium_robotics/{f[:-4]}", os.path.join(folder, f)) for f in ROBOTICS_FILES]


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
    out += [(label, lambda f=f: mujoco.MjModel.from_xml_path(f))
            for label, f in robotics_files()]
    return out


#: models refused for a real reason: label -> the reason (the ModelError must say so);
#: none since constraints beside free joints import (the quadruped's root, the
#: Fetch tasks' object, the kitchen's kettle: their equalities couple plain joints)
REFUSED: dict = {}


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


# -- every joint kind and frame on one synthetic model ----------------------------

#: hinge about a tilted axis with an anchor and a ref, several joints on one body
#: (slide then hinge), a ball joint with armature, a free body, springs with
#: springref, damping, a rotated body and rotated inertial frames
SYNTHETIC = """
<mujoco model="every joint">
  <option gravity="0.3 -0.2 -9.81"/>
  <worldbody>
    <body name="arm" pos="0.1 0.2 0.3" euler="10 20 30">
      <joint name="tilted" type="hinge" axis="1 2 3" pos="0.05 0 -0.1" ref="0.3"
             armature="0.02" damping="0.1" stiffness="2" springref="0.5"/>
      <geom type="box" size="0.1 0.2 0.3" pos="0 0 -0.2" euler="5 0 7" mass="1.3"/>
      <body name="carriage" pos="0 0 -0.5" quat="0.9 0.1 -0.3 0.2">
        <joint name="rail" type="slide" axis="0 1 0" ref="-0.1" stiffness="5"
               springref="0.2" armature="0.5"/>
        <joint name="wrist" type="hinge" axis="0 0 -1" pos="0.1 0 0" damping="0.3"/>
        <geom type="capsule" fromto="0 0 0 0.3 0.1 -0.2" size="0.04" mass="0.7"/>
        <body name="hand" pos="0.3 0.1 -0.2">
          <joint name="shoulder" type="ball" pos="0 0.05 0" armature="0.01" damping="0.2"/>
          <geom type="ellipsoid" size="0.1 0.05 0.08" pos="0.1 0 0" euler="0 30 60"
                mass="0.4"/>
        </body>
      </body>
    </body>
    <body name="puck" pos="1 0 0.5">
      <joint name="puck" type="free" damping="0.4"/>
      <geom type="box" size="0.2 0.1 0.05" euler="0 0 20" pos="0.1 0.05 0" mass="2"/>
    </body>
  </worldbody>
</mujoco>
"""


@pytest.mark.parametrize("formulation", ["aba", "crba"])
def test_every_joint_kind_matches_mujoco(formulation):
    imp = import_mjcf_text(SYNTHETIC, "synthetic.xml")
    spec = imp.model.spec()
    assert [j.kind for j in spec.joints] == ["ball", "free"]
    assert {k: float(v) for k, v in spec.armature} == {"tilted": 0.02, "rail": 0.5, "shoulder_wx": 0.01,
                                   "shoulder_wy": 0.01, "shoulder_wz": 0.01}
    check(mujoco.MjModel.from_xml_string(SYNTHETIC), "synthetic", formulation)


def test_state_conversions_round_trip():
    imp = import_mjcf_text(SYNTHETIC, "synthetic.xml")
    mjmodel = mujoco.MjModel.from_xml_string(SYNTHETIC)
    rng = np.random.default_rng(3)
    qpos = rng.normal(size=mjmodel.nq)
    for j in range(mjmodel.njnt):
        if mjmodel.jnt_type[j] in (0, 1):
            a = mjmodel.jnt_qposadr[j] + (3 if mjmodel.jnt_type[j] == 0 else 0)
            qpos[a:a + 4] /= np.linalg.norm(qpos[a:a + 4])
    qvel = rng.normal(size=mjmodel.nv)
    q = qpos_from_mujoco(imp, qpos)
    assert np.array_equal(qpos_to_mujoco(imp, q), qpos)
    v = qvel_from_mujoco(imp, qpos, qvel)
    assert np.allclose(qvel_to_mujoco(imp, q, v), qvel, rtol=0, atol=1e-14)
    # the free joint's linear velocity: world frame in MuJoCo, body frame in modelgen
    data = mujoco.MjData(mjmodel)
    data.qpos[:], data.qvel[:] = qpos, qvel
    mujoco.mj_forward(mjmodel, data)
    puck = mujoco.mj_name2id(mjmodel, mujoco.mjtObj.mjOBJ_BODY, "puck")
    spec = imp.model.spec()
    k = spec.dof_names.index("puck_vx")
    R = data.xmat[puck].reshape(3, 3)
    assert np.allclose(R @ v[k:k + 3], qvel[mjmodel.jnt_dofadr[-1]:][:3], atol=1e-14)


@pytest.mark.parametrize("equality", [
    "<joint joint1='rail' joint2='wrist' polycoef='0.1 -0.5 0.2 0 0'/>",
    "<connect body1='hand' body2='puck' anchor='0.1 0.05 0'/>"])
def test_equality_constraints_beside_ball_and_free_joints_match_mujoco(equality):
    """A coupling of two hinges, or a connect from the ball joint's body to the
    free body, on a model with both: the residuals against MuJoCo's violations and
    the tree dynamics (equalities off) as for the suites' models; the dependent
    coordinates are plain ones, chosen by modelgen."""
    text = SYNTHETIC.replace("</worldbody>", f"</worldbody><equality>{equality}</equality>")
    imp = import_mjcf_text(text, "eq.xml")
    result = check(mujoco.MjModel.from_xml_string(text), "synthetic_eq")
    assert result["worst"]["f"] <= EQUALITY_TOL
    chosen = modelgen.generate_model(imp.model).manifest["constraints"]["dependent"]
    plain = set(imp.model.spec().simple_coordinates)
    assert chosen and {name.removesuffix("_dot") for name in chosen} <= plain, chosen


def test_a_weld_through_a_ball_joint_is_refused():
    text = SYNTHETIC.replace("</worldbody>", "</worldbody><equality><weld body1='hand' "
                                             "body2='arm'/></equality>")
    with pytest.raises(ModelError, match="passes through the ball joint 'shoulder'") as info:
        import_mjcf_text(text, "eq.xml")
    assert info.value.key == "equality[0]" and info.value.file == "eq.xml"
    assert "connect" in info.value.fix


@pytest.mark.parametrize("first, second, hinges", [(4, 30, 26), (5, 19, 14), (0, 20, 14)])
def test_a_weld_too_many_hinges_apart_is_refused_at_once(first, second, hinges):
    """The limit counts the hinges on both sides of the common ancestor (a weld 26
    hinges down one branch built 2^26 terms before the count was checked: a hang
    in bench/fuzz.py --mjcf), and the refusal comes before any term is built."""
    def chain(prefix, n):
        return "".join(f'<body name="{prefix}{k}" pos="0 0 -0.1"><joint name="{prefix}j{k}" '
                       'axis="0 1 0"/><geom type="sphere" size="0.02" mass="0.1"/>'
                       for k in range(n)) + "</body>" * n
    text = (f"<mujoco><worldbody>{chain('d', 32)}</worldbody><equality><weld "
            f"body1='d{first}' body2='d{second}'/></equality></mujoco>")
    if first == 0:      # across two branches of the world: 14 = 7 + 7, each under 12
        text = (f"<mujoco><worldbody>{chain('a', 7)}{chain('b', 7)}</worldbody><equality>"
                "<weld body1='a6' body2='b6'/></equality></mujoco>")
    start = time.perf_counter()
    with pytest.raises(ModelError, match=f"through {hinges} hinges") as info:
        import_mjcf_text(text, "weld.xml")
    assert info.value.key == "equality[0]" and time.perf_counter() - start < 5.0


# -- equality constraints ------------------------------------------------------------

#: joint couplings (polycoef to the 4th power, refs, joint2 absent), a fixed-tendon
#: coupling, a connect through a tilted hinge's chain, two inactive equalities
COUPLINGS = """
<mujoco model="couplings">
  <worldbody>
    <body name="a" pos="0 0 1">
      <joint name="ha" axis="0 0 1" ref="0.2"/>
      <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.05" mass="1"/>
      <body name="b" pos="0.5 0 0" euler="0 10 0">
        <joint name="hb" axis="0 1 0"/>
        <joint name="sb" type="slide" axis="1 0 0" ref="0.1"/>
        <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.05" mass="0.8"/>
        <body name="c" pos="0.4 0 0">
          <joint name="hc" axis="1 1 0" pos="0.05 0 0"/>
          <geom type="box" size="0.1 0.05 0.02" mass="0.3"/>
          <site name="tip" pos="0.3 0 0.1"/>
        </body>
      </body>
    </body>
    <body name="d" pos="1 0 1">
      <joint name="hd" axis="1 0 0" ref="-0.3"/>
      <joint name="sd" type="slide" axis="0 0 1"/>
      <geom type="capsule" fromto="0 0 0 0 0.4 0" size="0.05" mass="0.5"/>
      <body name="e" pos="0 0.4 0">
        <joint name="he" axis="0 1 1"/>
        <geom type="sphere" size="0.1" mass="0.4"/>
        <site name="e_site" pos="0.1 0 0.05"/>
      </body>
    </body>
    <body name="knob" pos="0 -1 0">
      <joint name="k1" axis="0 0 1" ref="0.4"/>
      <geom type="box" size="0.1 0.2 0.05" mass="0.2"/>
    </body>
    <body name="burner" pos="0.5 -1 0">
      <joint name="k2" type="slide" axis="0 1 0" ref="0.25"/>
      <geom type="box" size="0.1 0.2 0.05" mass="0.2"/>
    </body>
    <body name="lamp" pos="1 -1 0">
      <joint name="k3" axis="1 0 0"/>
      <geom type="box" size="0.1 0.2 0.05" mass="0.2"/>
    </body>
  </worldbody>
  <tendon>
    <fixed name="t1"><joint joint="hb" coef="0.5"/><joint joint="hd" coef="-0.3"/></fixed>
    <fixed name="t2"><joint joint="k3" coef="1.5"/><joint joint="ha" coef="0.2"/></fixed>
    <spatial name="rope"><site site="tip"/><site site="e_site"/></spatial>
  </tendon>
  <equality>
    <joint name="coupled" joint1="k1" joint2="k2" polycoef="0.1 2 0.3 -0.2 0.05"/>
    <joint name="held" joint1="k3" polycoef="0.4 0 0 0 0"/>
    <tendon name="tendons" tendon1="t1" tendon2="t2" polycoef="0.05 0.7 0.1 0 0"/>
    <connect name="ball" body1="c" body2="e" anchor="0.3 0 0"/>
    <connect name="sites" site1="tip" site2="e_site" active="false"/>
    <joint name="off" joint1="ha" active="false"/>
  </equality>
</mujoco>
"""

#: a weld to a mocap body (body semantics, relpose from qpos0) and a weld of two
#: sites with torquescale, through tilted hinges and rotated bodies
WELDS = """
<mujoco model="welds">
  <worldbody>
    <body name="target" mocap="true" pos="0.3 0.2 0.9" quat="0.9 0.1 0.2 0.3"/>
    <body name="gripper" pos="0.3 0.2 0.8">
      <joint name="gx" type="slide" axis="1 0 0"/>
      <joint name="gy" type="slide" axis="0 1 0"/>
      <joint name="gz" type="slide" axis="0 0 1"/>
      <joint name="g1" axis="0 0 1" ref="0.1"/>
      <geom type="sphere" size="0.05" mass="0.5"/>
      <body name="wrist" pos="0.1 0 0" euler="20 0 10">
        <joint name="g2" axis="1 0 0"/>
        <joint name="g3" axis="0.3 0.4 0.5"/>
        <geom type="box" size="0.1 0.05 0.02" mass="0.3"/>
      </body>
    </body>
    <body name="p" pos="0 1 1">
      <joint name="p1" axis="0 0 1"/>
      <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.05" mass="1"/>
      <body name="p_end" pos="0.5 0 0">
        <joint name="p2" axis="1 0 0"/>
        <joint name="p3" type="slide" axis="1 0 0"/>
        <geom type="sphere" size="0.1" mass="0.4"/>
        <site name="p_site" pos="0.1 0.02 0" euler="10 20 30"/>
      </body>
    </body>
    <body name="r" pos="0.5 1.2 1">
      <joint name="r1" type="slide" axis="0 1 0"/>
      <joint name="r2" axis="0 0 1"/>
      <joint name="r3" axis="0 1 0"/>
      <joint name="r4" type="slide" axis="0 0 1"/>
      <geom type="box" size="0.1 0.2 0.05" mass="0.2"/>
      <site name="r_site" pos="0 0.1 0" euler="0 0 90"/>
    </body>
  </worldbody>
  <equality>
    <weld name="hold" body1="target" body2="wrist"/>
    <weld name="pair" site1="p_site" site2="r_site" torquescale="2"/>
  </equality>
</mujoco>
"""

#: a weld of two moving bodies with a given relpose, anchor and torquescale
RELPOSE = """
<mujoco model="relpose">
  <worldbody>
    <body name="p" pos="0 1 1">
      <joint name="p1" axis="0 0 1"/>
      <joint name="p2" type="slide" axis="1 0 0"/>
      <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.05" mass="1"/>
      <body name="p_end" pos="0.5 0 0">
        <joint name="p3" axis="1 0 0"/>
        <geom type="sphere" size="0.1" mass="0.4"/>
      </body>
    </body>
    <body name="r" pos="0.5 1.2 1">
      <joint name="r1" type="slide" axis="0 1 0"/>
      <joint name="r2" axis="0 1 0"/>
      <joint name="r3" type="slide" axis="0 0 1"/>
      <joint name="r4" axis="0 1 1"/>
      <geom type="box" size="0.1 0.2 0.05" mass="0.2"/>
    </body>
  </worldbody>
  <equality>
    <weld name="pair" body1="p_end" body2="r" relpose="0.1 0.2 0 0.8 0.2 0.3 0.1" anchor="0.05 0 0" torquescale="2"/>
  </equality>
</mujoco>
"""


def test_couplings_and_connect_match_mujocos_violations():
    imp = import_mjcf_text(COUPLINGS, "couplings.xml")
    kinds = [(c.name, c.kind) for c in imp.model.spec().constraints]
    assert kinds == [("coupled", "position"), ("held", "position"), ("tendons", "position"),
                     ("ball", "coincide")]
    assert 'Skipped: 2 inactive equality constraints (active="false"): sites, off.' \
        in imp.notes
    assert any("solref and solimp" in n for n in imp.notes)
    result = check(mujoco.MjModel.from_xml_string(COUPLINGS), "couplings")
    assert set(result["worst"]) == {"A", "h - tau", "f"}


@pytest.mark.parametrize("name", ["WELDS", "RELPOSE"])
def test_welds_match_mujocos_violations(name):
    text = globals()[name]
    imp = import_mjcf_text(text, f"{name}.xml")
    assert [e for e, _ in imp.equality_rows] == sorted(
        e for e in range(text.count("<weld")) for _ in range(6))
    check(mujoco.MjModel.from_xml_string(text), name.lower())


def test_constrained_import_round_trips_through_the_model_file():
    for text in (COUPLINGS, WELDS):
        imp = import_mjcf_text(text, "eq.xml")
        assert parse_model(mjcf_to_yaml(imp)) == imp.model.spec()


def test_manipulator_finger_coupling_matches_mujoco():
    pytest.importorskip("dm_control", reason="dm-control is not installed")
    check(*dmc_model("manipulator"))


def test_spatial_tendon_equality_is_refused():
    text = COUPLINGS.replace('<joint name="off" joint1="ha" active="false"/>',
                             '<tendon tendon1="rope"/>')
    with pytest.raises(ModelError, match="spatial tendon 'rope'") as info:
        import_mjcf_text(text, "rope.xml")
    assert info.value.key == "equality[5]"


def test_redundant_equalities_are_refused_when_generated(tmp_path):
    """MuJoCo accepts the same coupling twice (its soft rows share the load);
    modelgen's exact constraints would have a singular Jacobian."""
    text = COUPLINGS.replace('<joint name="off" joint1="ha" active="false"/>',
                             '<joint name="again" joint1="k3" polycoef="0.4 0 0 0 0"/>')
    imp = import_mjcf_text(text, "twice.xml")
    with pytest.raises(ModelError, match="redundant"):
        modelgen.generate_model(imp.model, tmp_path)


def test_mujoco_compile_errors_are_model_errors_at_mujocos_line(tmp_path):
    with pytest.raises(ModelError, match="MuJoCo cannot compile") as info:
        import_mjcf_text("<mujoco><worldbody>\n<body>\n<joint type='bogus'/></body>"
                         "</worldbody></mujoco>", "bad.xml")
    assert (info.value.file, info.value.line) == ("bad.xml", 3)
    assert "\n" not in str(info.value)          # MuJoCo's message on one line
    path = tmp_path / "bad.xml"
    path.write_text("<mujoco>\n<worldbody>\n<body>\n<geom size='-1'/></body></worldbody></mujoco>")
    with pytest.raises(ModelError, match="MuJoCo cannot compile the file") as info:
        modelgen.as_spec(path)
    assert (info.value.file, info.value.line) == (str(path), 4)
    # MuJoCo cuts its message at about 500 characters: after a long name, no line
    # (and "element", not "Element"); the element's line in the file
    name = "a" * 600
    path.write_text('<mujoco>\n<worldbody>\n<body name="b"><joint name="h"/><geom '
                    'type="sphere" size="0.1" mass="1"/></body>\n</worldbody>\n<equality>\n'
                    f'<connect body1="{name}" body2="world" anchor="0 0 0"/>\n'
                    "</equality></mujoco>")
    with pytest.raises(ModelError, match="unknown element 'aaa") as info:
        modelgen.as_spec(path)
    assert info.value.line == 6
    # no line from MuJoCo's engine, which names the body by its id
    with pytest.raises(ModelError, match="body 1 is compiled as simple") as info:
        import_mjcf_text('<mujoco><worldbody><body name="a"><joint name="h"/><geom '
                         'type="sphere" size="0.1" pos="0 0 nan" mass="1"/></body>'
                         "</worldbody></mujoco>", "bad.xml")
    assert (info.value.line, info.value.key) == (None, "body[1]")


#: MJCF that MuJoCo compiles (with a warning at most) into a NaN, an infinity or a
#: zero quaternion that the import would read: the key of the ModelError
NON_FINITE = {
    '<option gravity="0 0 nan"/>': "option.gravity",
    '<joint name="h" type="hinge" axis="0 1 0" damping="nan"/>': "joint[0].dof_damping",
    '<joint name="h" type="hinge" axis="0 1 0" stiffness="1" springref="inf"/>':
        "joint[0].qpos_spring",
    '<joint name="h" type="hinge" axis="0 1 0" pos="0 nan 0"/>': "joint[0].jnt_pos",
    '<geom type="capsule" size="0.1 0.5" quat="0.707 0 0.707 1e308"/>':
        "body[1].body_iquat",
    '<inertial pos="0 0 0" mass="1" diaginertia="1 2 3" quat="-1e-300 0 0 0"/>':
        "body[1].body_iquat",
}


@pytest.mark.parametrize("element", list(NON_FINITE))
def test_non_finite_compiled_numbers_are_model_errors(element):
    """A NaN damping was dropped silently (NaN > 0 is false) and a NaN or infinite
    position, or a zero inertia quaternion, ended in a raw ValueError (bench MJCF
    mutation runs); each is now refused naming the element and the field."""
    option = element if element.startswith("<option") else ""
    joint = element if "<joint" in element else '<joint name="h" type="hinge" axis="0 1 0"/>'
    geom = element if "<geom" in element or "<inertial" in element else \
        '<geom type="sphere" size="0.1" mass="1"/>'
    text = (f'<mujoco>{option}<worldbody><body name="rod">{joint}{geom}</body>'
            "</worldbody></mujoco>")
    with pytest.raises(ModelError, match="nan|inf|no unit quaternion") as info:
        import_mjcf_text(text, "bad.xml")
    assert info.value.file == "bad.xml" and info.value.key == NON_FINITE[element]
    assert "finite numbers in the MJCF" in str(info.value)


def test_load_and_import_dispatch_on_xml(tmp_path, capsys):
    from modelgen.cli import main
    path = tmp_path / "robot.xml"
    path.write_text(SYNTHETIC)
    assert modelgen.as_spec(path) == import_mjcf_text(SYNTHETIC, str(path)).model.spec()
    assert main(["import", str(path), "-o", str(tmp_path / "robot.yaml")]) == 0
    text = (tmp_path / "robot.yaml").read_text()
    assert "# Note: Ignored: 4 geoms (contacts)" in text
    assert parse_model(text) == modelgen.as_spec(path)
    assert "wrote" in capsys.readouterr().out


def test_frictionloss_is_a_smoothed_friction_effect_or_left_out_with_a_note():
    text = SYNTHETIC.replace('damping="0.3"/>', 'damping="0.3" frictionloss="0.25"/>')
    smooth = import_mjcf_text(text, "f.xml").model.spec()
    (friction,) = [e for e in smooth.effects if e.kind == "friction"]
    assert (friction.coordinate, float(friction.coulomb)) == ("wrist", 0.25)
    left_out = import_mjcf_text(text, "f.xml", frictionloss="ignore")
    assert not [e for e in left_out.model.spec().effects if e.kind == "friction"]
    assert any("frictionloss (left out as asked) of wrist" in n for n in left_out.notes)


def test_bodies_and_sites_are_frames_at_mujocos_poses(tmp_path):
    """Every body and site is a frame whose pose is MuJoCo's xpos/xmat and
    site_xpos/site_xmat, at random states of every joint kind."""
    xml = SYNTHETIC.replace(
        '<body name="hand" pos="0.3 0.1 -0.2">',
        '<body name="hand" pos="0.3 0.1 -0.2">\n'
        '          <site name="tip" pos="0.2 0.01 -0.03" euler="10 -20 30"/>')
    imp = import_mjcf_text(xml, "sites.xml")
    spec = imp.model.spec()
    mjmodel = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(mjmodel)
    names = [f.name for f in spec.frames]
    bodies = {mujoco.mj_id2name(mjmodel, mujoco.mjtObj.mjOBJ_BODY, b): b
              for b in range(1, mjmodel.nbody)}
    assert len(names) == len(bodies) + 1 and "tip" in names
    cm = modelgen.load(spec, tmp_path, frames=names)
    rng = np.random.default_rng(11)
    worst = 0.0
    for _ in range(3):
        data.qpos[:] = rng.normal(size=mjmodel.nq)
        mujoco.mj_normalizeQuat(mjmodel, data.qpos)
        mujoco.mj_kinematics(mjmodel, data)
        q = qpos_from_mujoco(imp, data.qpos)
        for name in names:
            T = cm.frame_pose(q, name)
            if name == "tip":
                expected = data.site_xpos[0], data.site_xmat[0].reshape(3, 3)
            else:
                b = bodies[name.removesuffix("_frame")]
                expected = data.xpos[b], data.xmat[b].reshape(3, 3)
            worst = max(worst, np.max(np.abs(T[:3, 3] - expected[0])),
                        np.max(np.abs(T[:3, :3] - expected[1])))
    assert worst <= 1e-12, worst
