"""The articulated-body algorithm against the CRBA path, and the joint-tree extraction.

The ABA program (modelgen.derive.aba) and the CRBA program (A, b = tau - h of
modelgen.derive.dynamics) are both evaluated in Python from their straight-line
programs; q_ddot must agree to 1e-12 relative (max norm) on every shipped
model, on spatial chains and on a branched tree with a prismatic joint, merged
bodies, constant rotations, an angle offset, an action, a spring and damping.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import sympy
from sympy.printing.pycode import pycode

import modelgen
from modelgen.cli import main
from modelgen.codegen.pipeline import choose_formulation
from modelgen.derive.aba import derive_aba
from modelgen.derive.dynamics import derive_equations
from modelgen.derive.joint_tree import extract_joint_tree, is_joint_tree
from modelgen.derive.kinematics import derive_kinematics
from modelgen.errors import MassMatrixError, ModelError
from modelgen.model.api import Model, load_model
from modelgen.model.chains import spatial_chain

from conftest import MODELS

#: constrained models are not joint trees (they close loops): see test_constraints.py
SHIPPED = sorted(str(p.relative_to(MODELS).with_suffix("")) for p in MODELS.glob("**/*.yaml")
                 if "scenes" not in p.parts and "\nconstraints:" not in p.read_text())


def _program(graph, outputs, inputs):
    """A Python function evaluating ``outputs`` of a straight-line program."""
    lines = ["def f(" + ", ".join(str(s) for s in inputs) + "):"]
    for sym, expr in graph.closure(outputs):
        lines.append(f"    {sym} = {pycode(expr)}")
    lines.append("    return [" + ", ".join(pycode(sympy.sympify(e)) for e in outputs) + "]")
    namespace = {"math": math}
    exec("\n".join(lines), namespace)     # noqa: S102 - our own generated program
    return namespace["f"]


def _qdd_both(spec, states=3, seed=0, velocity_products="auto"):
    """[(q_ddot by CRBA and a dense solve, q_ddot by ABA)] at seeded random states."""
    eqs = derive_equations(derive_kinematics(spec))
    fd = derive_aba(eqs, extract_joint_tree(spec), spec, velocity_products=velocity_products)
    n, nq = len(eqs.qd), len(eqs.q)
    inputs = (eqs.t,) + eqs.q + eqs.qd + eqs.u + eqs.p
    quaternions = [[spec.coordinates.index(c) for c in j.quaternion] for j in spec.joints]
    crba = _program(eqs.graph, [eqs.A[i][j] for i in range(n) for j in range(n)]
                    + [eqs.tau[k] - eqs.h[k] for k in range(n)], inputs)
    aba = _program(fd.graph, list(fd.qdd) + list(fd.D), inputs)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(states):
        q = rng.uniform(-1, 1, nq)
        for quat in quaternions:          # the equations hold for unit quaternions
            q[quat] /= np.linalg.norm(q[quat])
        values = ([0.3] + list(q) + list(rng.uniform(-1, 1, n))
                  + list(rng.uniform(-1, 1, len(eqs.u))) + list(spec.parameter_defaults))
        r = crba(*values)
        A, b = np.array(r[:n * n]).reshape(n, n), np.array(r[n * n:])
        s = aba(*values)
        assert all(d > 0 for d in s[n:])
        out.append((np.linalg.solve(A, b), np.array(s[:n])))
    return out


def _assert_agree(spec, rtol=1e-12, velocity_products="auto"):
    for crba, aba in _qdd_both(spec, velocity_products=velocity_products):
        assert np.max(np.abs(aba - crba)) <= rtol * np.max(np.abs(crba)), (crba, aba)


def branched_tree() -> Model:
    """A tree: a hub (q1), a slider on it (s), two arms on different branches
    (q2 with an angle offset and a second body fixed to it, q3 behind a constant
    rotation), a tip (q4) on arm a; gravity, an action, a spring, damping."""
    m = Model("branched", description="A branched tree with a prismatic joint.")
    m.add_coordinates("q1", "s", "q2", "q3", "q4")
    m.add_parameters({"m1": 1.2, "m2": 0.7, "m3": 0.9, "m4": 0.5, "m5": 0.3, "l": 0.4,
                      "g": 9.81, "k": 5.0, "c": 0.1})
    m.add_inputs("F")
    m.add_base("B1", parent="E", axis=3, angle="q1")
    m.add_point("P1", parent="O", base="B1", coordinates=["l", 0, "0.1"])
    m.add_body("hub", mass="m1", G="P1", base="B1",
               inertia=[[0.02, 0.001, 0], [0.001, 0.03, 0.002], [0, 0.002, 0.04]])
    m.add_point("S", parent="P1", base="B1", coordinates=["s + 0.2", 0, 0])
    m.add_body("slider", mass="m2", G="S", base="B1", inertia=[0.001, 0.002, 0.0025])
    m.add_base("B2", parent="B1", axis=1, angle="q2 + 0.3")
    m.add_point("G2", parent="S", base="B2", coordinates=[0, "l/2", 0])
    m.add_body("arm_a", mass="m3", G="G2", base="B2", inertia=[0.012, 0.001, 0.012])
    m.add_point("G2b", parent="S", base="B2", coordinates=["0.05", "l", "0.02"])
    m.add_body("weight_a", mass="m5", G="G2b", base="B2")
    m.add_base("B4", parent="B2", axis=3, angle="q4")
    m.add_point("T4", parent="S", base="B2", coordinates=[0, "l", 0])
    m.add_point("G4", parent="T4", base="B4", coordinates=["l/2", 0, 0])
    m.add_body("tip", mass="m4", G="G4", base="B4", inertia=[0.001, 0.006, 0.006])
    m.add_base("Bc", parent="B1", axis=3, angle="0.4")
    m.add_base("B3", parent="Bc", axis=2, angle="q3")
    m.add_point("P3", parent="P1", base="B1", coordinates=[0, "-l", 0])
    m.add_point("G3", parent="P3", base="B3", coordinates=["l/2", 0, 0])
    m.add_body("arm_b", mass="m3", G="G3", base="B3", inertia=[0.001, 0.012, 0.012])
    m.set_gravity([0, "-g", 0])
    m.add_action("push", body="arm_b", point="G3", base="B3", force=["F", 0, 0],
                 torque=[0, 0, "F/10"])
    m.add_effect("spring", "spring", point_a="G4", point_b="G3", stiffness="k",
                 rest_length="l")
    m.add_effect("hinges", "joint_damping", coordinates=["q2", "q3"], damping="c")
    return m


# -- joint-tree extraction ------------------------------------------------------------

def test_every_shipped_model_is_a_joint_tree():
    for name in SHIPPED:
        assert is_joint_tree(load_model(MODELS / f"{name}.yaml")), name


def test_joint_tree_of_the_branched_model_has_its_branches_and_merged_bodies():
    tree = extract_joint_tree(branched_tree().spec())
    joints = {j.name: j for j in tree.joints}
    parent = {j.name: tree.joints[j.parent].name if j.parent >= 0 else None
              for j in tree.joints}
    assert parent == {"q1": None, "s": "q1", "q2": "s", "q4": "q2", "q3": "q1"}
    assert joints["s"].kind == "prismatic" and joints["s"].S == (0, 0, 0, 1, 0, 0)
    assert joints["q2"].kind == "revolute" and joints["q2"].axis == 1
    bodies = {j.name: tree.inertias[i].bodies for i, j in enumerate(tree.joints)}
    assert bodies["q2"] == ("arm_a", "weight_a")
    assert bodies["q1"] == ("hub",)


def _chain_with(point_coordinates=("l", 0, 0), angle2="q2"):
    m = Model("bad")
    m.add_coordinates("q1", "q2")
    m.add_parameters({"l": 1.0, "m": 1.0})
    m.add_base("B1", parent="E", axis=3, angle="q1")
    m.add_base("B2", parent="B1", axis=3, angle=angle2)
    m.add_point("P1", parent="O", base="B1", coordinates=list(point_coordinates))
    m.add_point("G2", parent="P1", base="B2", coordinates=["l", 0, 0])
    m.add_body("b1", mass="m", G="P1", base="B1")
    m.add_body("b2", mass="m", G="G2", base="B2")
    return m.spec()


@pytest.mark.parametrize("kwargs, key, words", [
    ({"point_coordinates": ("l", "q2", 0)}, "points.P1.coordinates", "enters"),
    ({"point_coordinates": ("l*cos(q2)", 0, 0), "angle2": "0.5"}, "points.P1.coordinates",
     "not linear"),
    ({"angle2": "q2 + q1"}, "bases.B2.angle", "enters"),
    ({"angle2": "q2**2"}, "bases.B2.angle", "is not one coordinate"),
])
def test_not_a_joint_tree_names_the_offending_expression(kwargs, key, words):
    spec = _chain_with(**kwargs)
    with pytest.raises(ModelError) as info:
        extract_joint_tree(spec)
    assert info.value.key == key and words in str(info.value)
    assert "not a joint tree" in str(info.value)
    assert choose_formulation(spec, "auto") == ("crba", None)
    with pytest.raises(ModelError):
        choose_formulation(spec, "aba")


def test_a_point_off_the_bodys_base_path_is_not_a_joint_tree():
    m = Model("off_path")
    m.add_coordinates("q1", "q2")
    m.add_parameters({"l": 1.0, "m": 1.0})
    m.add_base("B1", parent="E", axis=3, angle="q1")
    m.add_base("B2", parent="B1", axis=2, angle="q2")
    m.add_point("G", parent="O", base="B2", coordinates=["l", 0, 0])
    m.add_body("b", mass="m", G="G", base="B1")
    with pytest.raises(ModelError, match="not on the way from E") as info:
        extract_joint_tree(m.spec())
    assert info.value.key == "points.G.base"


def test_one_rotation_about_two_places_is_not_one_joint():
    m = Model("two_places")
    m.add_coordinates("q1")
    m.add_parameters({"l": 1.0, "m": 1.0})
    m.add_base("B1", parent="E", axis=3, angle="q1")
    m.add_point("GA", parent="O", base="B1", coordinates=["l", 0, 0])
    m.add_point("P", coordinates=[1, 0, 0])
    m.add_point("GB", parent="P", base="B1", coordinates=["l", 0, 0])
    m.add_body("a", mass="m", G="GA", base="B1")
    m.add_body("b", mass="m", G="GB", base="B1")
    with pytest.raises(ModelError, match="not one joint") as info:
        extract_joint_tree(m.spec())
    assert info.value.key == "bases.B1.angle"


def test_a_coordinate_that_moves_no_body_is_reported():
    m = Model("idle")
    m.add_coordinates("q1", "q2")
    m.add_parameters({"l": 1.0, "m": 1.0})
    m.add_base("B1", parent="E", axis=3, angle="q1")
    m.add_base("B9", parent="E", axis=1, angle="q2")
    m.add_point("G", parent="O", base="B1", coordinates=["l", 0, 0])
    m.add_body("b", mass="m", G="G", base="B1")
    with pytest.raises(ModelError, match="'q2' moves no body"):
        extract_joint_tree(m.spec())


def test_unknown_formulation_is_a_model_error():
    with pytest.raises(ModelError, match="unknown formulation"):
        choose_formulation(spatial_chain(2).spec(), "featherstone")


# -- agreement with the CRBA path ---------------------------------------------------

# both places of the velocity-product accelerations (derive_aba's velocity_products;
# "auto" keeps one of the two programs)
VP = ("inward", "outward")


@pytest.mark.parametrize("vp", VP)
@pytest.mark.parametrize("name", SHIPPED)
def test_aba_matches_crba_on_every_shipped_model(name, vp):
    _assert_agree(load_model(MODELS / f"{name}.yaml"), velocity_products=vp)


@pytest.mark.parametrize("vp", VP)
@pytest.mark.parametrize("n", [2, 5, 12])     # n = 1 has q_ddot = 0 (gravity along the axis)
def test_aba_matches_crba_on_spatial_chains(n, vp):
    _assert_agree(spatial_chain(n).spec(), velocity_products=vp)


@pytest.mark.parametrize("vp", VP)
def test_aba_matches_crba_on_a_branched_tree(vp):
    _assert_agree(branched_tree().spec(), velocity_products=vp)


def test_auto_plan_is_no_longer_than_either_program():
    # the spatial chain's rods (centre on the axis, diagonal inertia) send c
    # outwards below the first joints; the arm's full inertias off the axes
    # keep it inwards but at the last link, where a_vp = c needs no transform;
    # the heavy top's symmetric body keeps its articulated inertias sparse,
    # so Ia c is cheap
    for spec, plan in ((spatial_chain(12).spec(), ".." + "o" * 10),
                       (load_model(MODELS / "arm7.yaml"), "......o"),
                       (load_model(MODELS / "heavy_top.yaml"), "..."),
                       (branched_tree().spec(), None)):
        eqs = derive_equations(derive_kinematics(spec))
        tree = extract_joint_tree(spec)
        fds = {vp: derive_aba(eqs, tree, spec, velocity_products=vp) for vp in VP + ("auto",)}
        if plan is not None:
            assert "".join("o" if x else "." for x in fds["auto"].outward) == plan, spec.name
        ops = {vp: fd.graph.operations(fd.qdd + fd.D) for vp, fd in fds.items()}
        assert ops["auto"] <= min(ops["inward"], ops["outward"]), (spec.name, ops)
        assert ops["inward"] != ops["outward"]
    with pytest.raises(ValueError, match="velocity_products"):
        derive_aba(eqs, tree, spec, velocity_products="sideways")


def test_aba_matches_crba_when_gravity_is_an_effect_in_a_moving_base():
    # gravity fixed in B1 is not a ground acceleration: it must go through tau
    m = branched_tree()
    m.add_effect("wind", "gravity", vector=[0.5, 0, "-g/10"], base="B1")
    _assert_agree(m.spec())


def test_aba_matches_crba_with_scaled_joints_and_joint_forces():
    # S_j is not 1 (angles 2*q1 and -q2 + 0.1, a slider 3*s along a base axis) and
    # joint forces enter every u: the exact entries -1/S_j of -U/D and tau/S_j of pa
    m = Model("scaled", description="Joints whose motion subspace entry is not 1.")
    m.add_coordinates("q1", "s", "q2", "q3")
    m.add_parameters({"m1": 1.1, "m2": 0.6, "m3": 0.8, "l": 0.5, "g": 9.81, "k": 3.0,
                      "c": 0.2})
    m.add_base("B1", parent="E", axis=2, angle="2*q1")
    m.add_point("G1", parent="O", base="B1", coordinates=["l/2", "0.05", 0])
    m.add_body("link1", mass="m1", G="G1", base="B1",
               inertia=[[0.02, 0.001, 0.003], [0.001, 0.03, 0.002], [0.003, 0.002, 0.04]])
    m.add_point("S", parent="O", base="B1", coordinates=["l", 0, "3*s"])
    m.add_body("carriage", mass="m2", G="S", base="B1", inertia=[0.001, 0.002, 0.0025])
    m.add_base("B2", parent="B1", axis=1, angle="-q2 + 0.1")
    m.add_point("G2", parent="S", base="B2", coordinates=[0, "l/2", "0.1"])
    m.add_body("link2", mass="m3", G="G2", base="B2", inertia=[0.012, 0.002, 0.01])
    m.add_base("B3", parent="B2", axis=3, angle="q3")
    m.add_point("P3", parent="S", base="B2", coordinates=[0, "l", 0])
    m.add_point("G3", parent="P3", base="B3", coordinates=["l/2", "0.02", 0])
    m.add_body("link3", mass="m1", G="G3", base="B3", inertia=[0.001, 0.006, 0.005])
    m.set_gravity([0, 0, "-g"])
    m.add_effect("twist", "torsion_spring", coordinate="q2", stiffness="k", rest_angle="0.2")
    m.add_effect("damping", "joint_damping", coordinates=["q1", "s", "q2", "q3"],
                 damping="c")
    tree = extract_joint_tree(m.spec())
    assert sorted(str(x) for j in tree.joints for x in j.S if x != 0) == ["-1", "1", "2", "3"]
    _assert_agree(m.spec())


def test_aba_rhs_operation_count_does_not_regress():
    # bench/aba_scaling.py's figures (README): after CSE, per coordinate, as C
    # operators (codegen.printer.c_operations), 240 on the 20-link chain and 223 on
    # the arm; the margins allow small changes of the CSE
    from modelgen.codegen.cse import make_routines
    from modelgen.codegen.pipeline import routines_for
    for spec, limit in ((spatial_chain(20).spec(), 245), (load_model(MODELS / "arm7.yaml"), 228)):
        eqs = derive_equations(derive_kinematics(spec))
        fd = derive_aba(eqs, extract_joint_tree(spec), spec)
        (rhs,) = make_routines(fd.graph, [r for r in routines_for(eqs, (), None, fd)
                                          if r[0] == "rhs"])
        assert rhs.ops_after / spec.n <= limit, (spec.name, rhs.ops_after / spec.n)


# -- agreement with an independent engine (Pinocchio) --------------------------------

def _chain_against_pinocchio(n, seed, mass_matrix=False):
    """(modelgen, Pinocchio) pairs of q_ddot (ABA), h (RNEA) and A at seeded random
    states and random parameters of ``spatial_chain(n)``."""
    pin = pytest.importorskip("pinocchio")
    from modelgen.bench.peers import chain_pinocchio
    from modelgen.derive.graph import GraphBuilder
    from modelgen.derive.rnea import derive_velocity_terms
    spec = spatial_chain(n).spec()
    tree = extract_joint_tree(spec)
    eqs = derive_equations(derive_kinematics(spec))
    g = GraphBuilder(eqs.graph)
    h = derive_velocity_terms(g, tree, eqs.qd)
    fd = derive_aba(eqs, tree, spec, g.freeze())
    inputs = (eqs.t,) + eqs.q + eqs.qd + eqs.u + eqs.p
    f = _program(fd.graph, list(fd.qdd) + list(h)
                 + ([eqs.A[i][j] for i in range(n) for j in range(n)] if mass_matrix else []),
                 inputs)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(3):
        p = dict(zip((str(s) for s in eqs.p), rng.uniform(0.5, 1.5, len(eqs.p))))
        p["r"], p["g"] = 0.02 * p["r"], 9.81 * p["g"]
        model = chain_pinocchio(n, p)
        data = model.createData()
        x = rng.uniform(-1, 1, 2 * n)
        r = np.array(f(0.0, *x, *(p[str(s)] for s in eqs.p)))
        qdd = pin.aba(model, data, x[:n], x[n:], np.zeros(n))
        model.gravity.linear = np.zeros(3)
        h_pin = pin.rnea(model, data, x[:n], x[n:], np.zeros(n))
        pairs = [(r[:n], qdd), (r[n:2 * n], h_pin)]
        if mass_matrix:
            A_pin = pin.crba(model, data, x[:n])
            pairs.append((r[2 * n:].reshape(n, n), np.triu(A_pin) + np.triu(A_pin, 1).T))
        out.append(pairs)
    return out


def test_aba_and_rnea_match_pinocchio_on_a_30_link_chain():
    # ABA against ABA of an independent engine: no cond(A) in the comparison
    # (the CRBA path's solve limits agreement with it to about n = 20)
    for pairs in _chain_against_pinocchio(30, seed=7):
        for ours, theirs in pairs:
            assert np.max(np.abs(ours - theirs)) <= 1e-12 * np.max(np.abs(theirs))


def test_aba_rnea_and_mass_matrix_match_pinocchio_on_a_10_link_chain():
    for pairs in _chain_against_pinocchio(10, seed=8, mass_matrix=True):
        for ours, theirs in pairs:
            assert np.max(np.abs(ours - theirs)) <= 1e-12 * np.max(np.abs(theirs))


# -- generated C ----------------------------------------------------------------------

def test_generated_aba_rhs_and_jacobian_match_crba(build_root, capsys):
    path = MODELS / "cart_pole.yaml"
    crba_dir = build_root / "cart_pole_crba_jac"
    assert main(["generate", str(path), "-o", str(crba_dir), "--formulation", "crba",
                 "--jacobian"]) == 0
    assert "formulation crba" in capsys.readouterr().out
    crba = modelgen.load(path, crba_dir, formulation="crba", jacobian=True)
    aba = modelgen.load(path, build_root / "cart_pole_aba_jac", formulation="aba",
                        jacobian=True)
    assert (crba.manifest["formulation"], aba.manifest["formulation"]) == ("crba", "aba")
    rng = np.random.default_rng(3)
    for _ in range(3):
        x = rng.uniform(-1, 1, 4)
        u = rng.uniform(-1, 1, 1)
        a, b = crba.rhs(0.2, x, u), aba.rhs(0.2, x, u)
        assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(a))
        Ja, Jb = crba.jac(0.2, x, u), aba.jac(0.2, x, u)
        assert np.max(np.abs(Ja - Jb)) <= 1e-12 * np.max(np.abs(Ja))


def test_generated_aba_rhs_reports_a_vanishing_articulated_inertia(build_root):
    cm = modelgen.load(MODELS / "cart_pole.yaml", build_root / "cart_pole_aba_jac",
                       formulation="aba", jacobian=True)
    p = cm.params()
    p[[name for name, _ in cm.manifest["parameters"]].index("L")] = 0.0   # no pole length
    with pytest.raises(MassMatrixError) as info:
        cm.rhs(0.0, [0.0, 0.3, 0.0, 0.0], [0.0], p)
    assert info.value.coordinate == "theta"     # the joint where D vanishes, not its parent


def test_aba_simulation_stops_at_a_massless_link(compiled):
    cm = compiled("double_pendulum")
    assert cm.manifest["formulation"] == "aba"          # auto picks aba for a joint tree
    res = cm.simulate([0.5, -0.3, 0, 0], (0, 1), method="rk4", step=1e-2,
                      p={"m1": 0.0, "m2": 0.0})
    assert res.status == -3 and "coordinate 'q2'" in res.message   # the outer link first
