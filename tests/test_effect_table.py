"""Effects are one table: each kind is one dataclass plus one derive function.

Proves that the registries (EFFECT_KINDS, EFFECT_FIELD_ROLES, STIFF_KINDS,
CONSERVATIVE_KINDS) are derived from the dataclasses and say what the old
hand-written tables said, that every kind has its derive function, and that a
new kind needs only its dataclass and its function: a kind defined here is
loaded, written, read back, put in a scene and derived without touching any
other module.
"""
from __future__ import annotations

import dataclasses
from typing import ClassVar

import pytest
import sympy

import modelgen.model.spec as specmod
from modelgen.derive.dynamics import derive_equations
from modelgen.derive.effects import DERIVATIONS, EffectTerms
from modelgen.derive.graph import GraphBuilder
from modelgen.errors import ModelError
from modelgen.derive.kinematics import derive_kinematics
from modelgen.model import parse_model, parse_scene, spec_to_yaml
from modelgen.model.spec import (CONSERVATIVE_KINDS, EFFECT_FIELD_ROLES, EFFECT_KINDS,
                                 EFFECT_TYPES, FIELD_ROLES, STIFF_KINDS, ActionSpec, symbol)

#: The tables as they were written out by hand before the effects became one table.
OLD_FIELD_ROLES = {
    "point_a": "point", "point_b": "point", "point": "point", "body": "body",
    "base": "base", "coordinate": "coordinate", "coordinates": "coordinates",
    "vector": "vector",
    "stiffness": "nonnegative", "rest_length": "nonnegative", "damping": "nonnegative",
    "coulomb": "nonnegative", "viscous": "nonnegative", "static": "nonnegative",
    "density": "nonnegative", "drag_coefficient": "nonnegative", "area": "nonnegative",
    "stribeck_speed": "positive", "smoothing_speed": "positive",
    "preload": "signed", "rest_angle": "signed",
}
OLD_STIFF_KINDS = ("spring", "torsion_spring", "friction")
OLD_CONSERVATIVE_KINDS = ("gravity", "spring", "torsion_spring")


def test_every_effect_class_has_roles_flags_and_a_derive_function():
    for cls in EFFECT_TYPES + (ActionSpec,):
        fields = {f.name for f in dataclasses.fields(cls)} - {"name"}
        assert set(cls.roles) == fields, cls.kind
        assert set(cls.roles.values()) <= set(FIELD_ROLES), cls.kind
        assert isinstance(cls.stiff, bool) and isinstance(cls.conservative, bool), cls.kind
        assert cls in DERIVATIONS, cls.kind
    assert set(DERIVATIONS) == set(EFFECT_TYPES) | {ActionSpec}


def test_registries_are_derived_and_agree_with_the_old_tables():
    assert EFFECT_KINDS == {**{cls.kind: cls for cls in EFFECT_TYPES}, "action": ActionSpec}
    assert STIFF_KINDS == OLD_STIFF_KINDS
    assert CONSERVATIVE_KINDS == OLD_CONSERVATIVE_KINDS
    effect_roles = {k: v for k, v in EFFECT_FIELD_ROLES.items() if k not in ("torque", "force")}
    assert effect_roles == OLD_FIELD_ROLES
    # a field means the same in every kind that has it
    for cls in EFFECT_KINDS.values():
        for field, role in cls.roles.items():
            assert EFFECT_FIELD_ROLES[field] == role, (cls.kind, field)


@dataclasses.dataclass(frozen=True)
class ConstantTorqueEffect:
    """A test-only kind: a constant generalized force ``torque`` on one coordinate."""
    name: str
    coordinate: str
    torque: sympy.Expr
    stiff_hint: sympy.Expr = sympy.S.One
    kind = "constant_torque"
    roles: ClassVar[dict] = {"coordinate": "coordinate", "torque": "signed",
                             "stiff_hint": "positive"}
    stiff = True
    conservative = False


def _constant_torque(g: GraphBuilder, kin, eff) -> EffectTerms:
    k = kin.spec.coordinates.index(eff.coordinate)
    tau = [sympy.S.Zero] * kin.spec.n
    tau[k] = eff.torque
    return EffectTerms(generalized=tuple(g.name(x) for x in tau))


MODEL = """
name: wheel
coordinates: [q]
parameters: {I: 2.0, M: 0.5, h: 3.0}
bases: {B: {parent: E, axis: 3, angle: q}}
bodies: {disc: {mass: 1, G: O, base: B, inertia: [I, I, I]}}
effects:
  motor: {type: constant_torque, coordinate: q, torque: -M, stiff_hint: h}
"""


def test_a_new_kind_needs_only_its_dataclass_and_its_function(monkeypatch, tmp_path):
    monkeypatch.setitem(specmod.EFFECT_KINDS, "constant_torque", ConstantTorqueEffect)
    monkeypatch.setitem(DERIVATIONS, ConstantTorqueEffect, _constant_torque)

    spec = parse_model(MODEL)
    assert spec.effects == (ConstantTorqueEffect("motor", "q", -symbol("M"), symbol("h")),)
    assert parse_model(spec_to_yaml(spec)) == spec

    eqs = derive_equations(derive_kinematics(spec))
    expand = eqs.graph.expand
    assert sympy.simplify(expand(eqs.tau[0]) + symbol("M")) == 0
    assert sympy.simplify(expand(eqs.A[0][0]) - symbol("I")) == 0

    (tmp_path / "wheel.yaml").write_text(MODEL)
    scene = parse_scene("scene: spin\nmodel: wheel.yaml\neffects: [motor]\n"
                        "initial: {q: 0.0, q_dot: 0.0}\ntime: {end: 1.0, sample: 0.1}\n",
                        base_dir=tmp_path)
    assert scene.stiff_effects == ("motor",)
    assert scene.model.parameter_names == ("I", "M", "h")


def test_a_new_kind_field_is_checked_by_its_role(monkeypatch):
    monkeypatch.setitem(specmod.EFFECT_KINDS, "constant_torque", ConstantTorqueEffect)
    bad = MODEL.replace("stiff_hint: h", "stiff_hint: -h")
    with pytest.raises(ModelError, match="stiff_hint of constant_torque 'motor' is negative"):
        parse_model(bad, source="wheel.yaml")
