"""The recursive derivatives' per-dof vectors by kernels per joint signature
(derive/link_kernels.py): the same derivatives as the straight line they
replace, and as Pinocchio's, on chains, URDF robots (fixed rotations between
joints, full inertias, joint damping, a motor on every joint: d qdd / d u) and
the 29-dof G1 humanoid on a fixed base; the trees they do not take keep the
straight line."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy

import modelgen
from modelgen.codegen import tree_derivatives
from modelgen.derive import rnea_partials
from modelgen.derive.dynamics import derive_equations
from modelgen.derive.joint_tree import extract_joint_tree
from modelgen.derive.kinematics import derive_kinematics
from modelgen.derive.rnea_partials import derive_rnea_partials
from modelgen.model.chains import spatial_chain
from modelgen.model.urdf import import_urdf

from test_derivatives import QDD_DERIVATIVES_TOL, URDF, _check_against_pinocchio, _relative

REPO = Path(__file__).resolve().parents[1]


def _kernels_of(spec):
    tree = extract_joint_tree(spec)
    eqs = derive_equations(derive_kinematics(spec))
    return derive_rnea_partials(eqs, tree, spec, looped=True).kernels


def _looped(cm) -> bool:
    return f"{cm.name}_derivative_forward0" in (Path(cm.path).parent / f"{cm.name}.c").read_text()


@pytest.mark.parametrize("articulated", [False, True])
def test_looped_derivatives_are_the_straight_lines(articulated, tmp_path, monkeypatch):
    if articulated:
        monkeypatch.setattr(rnea_partials, "ARTICULATED_SOLVE_ABOVE", 0)
    spec = spatial_chain(12).spec()
    looped = modelgen.load(spec, tmp_path / "looped", derivatives=True)
    monkeypatch.setattr(tree_derivatives, "LOOPED", False)
    straight = modelgen.load(spec, tmp_path / "straight", derivatives=True)
    assert _looped(looped) and not _looped(straight)
    kernels = looped.manifest["derivative_kernels"]
    assert (kernels["signatures"], kernels["joints"]) == (3, 12) and kernels["operations"] > 0
    assert "derivative_kernels" not in straight.manifest
    rng = np.random.default_rng(5)
    for _ in range(3):
        x = np.concatenate([rng.uniform(-3, 3, 12), rng.uniform(-2, 2, 12)])
        for got, want in zip(looped.derivatives(0.0, x), straight.derivatives(0.0, x),
                             strict=True):
            assert _relative(got, want) <= 1e-12
        a = rng.uniform(-2, 2, 12)
        for got, want in zip(looped.inverse_dynamics_derivatives(0.0, x, a),
                             straight.inverse_dynamics_derivatives(0.0, x, a), strict=True):
            assert _relative(got, want) <= 1e-12


def test_actions_fixed_to_links_take_the_loop_over_their_inputs(tmp_path, monkeypatch):
    # a thrust across the tip link and a torque on a middle link about its own x
    # axis: body-fixed forces that are not a joint's motor, whose d Q / d u the
    # loop adds up the tree at run time
    model = spatial_chain(12).add_inputs("F", "T")
    model.add_action("thrust", body="rod12", point="G12", base="B12", force=[0, "F", 0])
    model.add_action("twist", body="rod6", point="G6", base="B6", torque=["T", 0, 0])
    spec = model.spec()
    looped = modelgen.load(spec, tmp_path / "looped", derivatives=True)
    source = (Path(looped.path).parent / f"{looped.name}.c").read_text()
    assert _looped(looped) and f"{looped.name}_ddu[" in source
    monkeypatch.setattr(tree_derivatives, "LOOPED", False)
    straight = modelgen.load(spec, tmp_path / "straight", derivatives=True)
    rng = np.random.default_rng(6)
    for _ in range(3):
        x = np.concatenate([rng.uniform(-3, 3, 12), rng.uniform(-2, 2, 12)])
        u = rng.uniform(-2, 2, 2)
        for got, want in zip(looped.derivatives(0.0, x, u), straight.derivatives(0.0, x, u),
                             strict=True):
            assert _relative(got, want) <= 1e-12


def test_joints_of_one_signature_share_a_kernel():
    # the root (the ground folded in), then joints about z and about y alternating
    k = _kernels_of(spatial_chain(20).spec())
    assert len(k.forward) == 3
    assert k.signature == (0,) + (1, 2) * 9 + (1,)
    assert k.parent == tuple(range(-1, 19)) and k.dof == tuple(range(20))
    # the table holds each joint's constants, one after the other (the root's
    # include the ground's acceleration, folded into its kernel)
    assert k.offset[0] == 0 and list(k.offset) == sorted(k.offset)
    assert len(k.table) > k.offset[-1]


def test_a_slot_is_never_the_number_of_its_index():
    # E with entries 0 and 1 against E with two constants first seen there: the
    # slots numbered 0 and 1 must not make the same key as those numbers
    from types import SimpleNamespace
    from modelgen.derive.joint_tree import LinkInertia
    from modelgen.derive.link_kernels import signature
    c, s = sympy.Rational(3, 5), sympy.Rational(4, 5)
    body = LinkInertia((1, 1, 1, 0, 0, 0), (0, 0, 0), 1, ())

    def joint(E):
        return SimpleNamespace(name="q", kind="revolute", axis=3, angle=sympy.Symbol("q"),
                               fixed=(E, (0, 0, 0)), S=(0, 0, 1, 0, 0, 0))
    plain, _ = signature(joint(((1, 0, 0), (0, 0, 1), (0, 1, 0))), body)
    turned, values = signature(joint(((1, 0, 0), (0, c, s), (0, s, c))), body)
    assert values == (c, s) and plain != turned


def _same_derivatives(spec, tmp_path, monkeypatch, seed=0, states=3):
    """Build ``spec`` looped and as a straight line; the derivatives agree."""
    looped = modelgen.load(spec, tmp_path / "looped", derivatives=True)
    assert _looped(looped)
    with monkeypatch.context() as m:
        m.setattr(tree_derivatives, "LOOPED", False)
        straight = modelgen.load(spec, tmp_path / "straight", derivatives=True)
    assert not _looped(straight)
    rng = np.random.default_rng(seed)
    for _ in range(states):
        x = np.concatenate([rng.uniform(-1, 1, looped.nq), rng.uniform(-1, 1, looped.n)])
        u = rng.uniform(-1, 1, len(looped.inputs))
        for got, want in zip(looped.derivatives(0.0, x, u), straight.derivatives(0.0, x, u),
                             strict=True):
            assert _relative(got, want) <= 1e-12


@pytest.mark.parametrize("articulated", [False, True])
def test_a_branched_tree_with_a_prismatic_joint_and_offsets_takes_the_loops(
        articulated, tmp_path, monkeypatch):
    # a prismatic joint, an angle q2 + 3/10, two branches, a force along the input F
    from test_aba import branched_tree
    monkeypatch.setattr(tree_derivatives, "FORWARD_DERIVATIVES_MAX", 0)
    if articulated:
        monkeypatch.setattr(rnea_partials, "ARTICULATED_SOLVE_ABOVE", 0)
    _same_derivatives(branched_tree().spec(), tmp_path, monkeypatch, seed=2)


def test_armature_enters_the_looped_articulated_factor(tmp_path, monkeypatch):
    monkeypatch.setattr(rnea_partials, "ARTICULATED_SOLVE_ABOVE", 0)
    model = spatial_chain(12)
    model.set_armature({f"q{i}": 0.05 * i for i in range(1, 13)})
    assert len(_kernels_of(model.spec()).armature) == 12
    _same_derivatives(model.spec(), tmp_path, monkeypatch, seed=3)


def test_trees_the_kernels_do_not_take_keep_the_straight_line():
    from test_armature import TUMBLER
    from modelgen.model import parse_model
    assert _kernels_of(spatial_chain(3).spec()) is not None
    # a free joint (a floating base), with its quaternion
    assert _kernels_of(parse_model(TUMBLER)) is None
    solo = import_urdf(URDF / "solo12.urdf", floating_base=True)
    assert _kernels_of(solo.model.spec()) is None


@pytest.fixture(scope="module")
def pin():
    return pytest.importorskip("pinocchio")


@pytest.mark.parametrize("robot", ["ur5_robot", "kinova"])
def test_looped_derivatives_of_urdf_robots_match_pinocchio(robot, pin, tmp_path, monkeypatch):
    from test_urdf import _pinocchio_maps
    # a few dofs: kept on the recursive derivatives, which then take the loops
    monkeypatch.setattr(tree_derivatives, "FORWARD_DERIVATIVES_MAX", 0)
    imp = import_urdf(URDF / f"{robot}.urdf")
    cm = modelgen.load(imp.model, tmp_path / "build", derivatives=True)
    assert len(cm.inputs) == cm.n                       # a motor on every joint
    assert _looped(cm)
    model = pin.buildModelFromUrdf(str(URDF / f"{robot}.urdf"))
    q_of, jmap = _pinocchio_maps(model, imp)
    damping = np.array([j.damping for j in imp.joints if j.coordinate is not None])
    assert _check_against_pinocchio(pin, cm, model, P=jmap, q_pin=q_of,
                                    damping=damping) <= QDD_DERIVATIVES_TOL


def test_looped_derivatives_of_the_g1_humanoid_match_pinocchio(pin, tmp_path):
    from test_urdf import _pinocchio_maps
    path = URDF / "g1_29dof_rev_1_0.urdf"
    imp = import_urdf(path)
    cm = modelgen.load(imp.model, tmp_path / "build", derivatives=True)
    assert cm.n == 29 and len(cm.inputs) == 29 and _looped(cm)
    model = pin.buildModelFromUrdf(str(path))
    q_of, jmap = _pinocchio_maps(model, imp)
    damping = np.array([j.damping for j in imp.joints if j.coordinate is not None])
    assert _check_against_pinocchio(pin, cm, model, P=jmap, q_pin=q_of, damping=damping,
                                    states=2) <= QDD_DERIVATIVES_TOL
