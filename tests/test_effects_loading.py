"""Effects in model files and the Python API: loading, defaults, round trips, errors."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import sympy

from modelgen.errors import ModelError
from modelgen.model import EFFECT_FIELD_ROLES, EFFECT_KINDS, Model, load_model, parse_model, \
    spec_to_yaml
from modelgen.model.spec import (EFFECT_TYPES, ActionSpec, DamperEffect, DragEffect, FrictionEffect,
                           GravityEffect, JointDampingEffect, SpringEffect, TorsionSpringEffect,
                           symbol)

ROOT = Path(__file__).resolve().parent.parent
Z = sympy.Integer(0)

# lines 1-9; effects snippets start at line 10
HEADER = """name: m
coordinates: [x1, x2]
parameters: {k: 10.0, c: 0.5, L: 1.0, mu: 0.3}
inputs: [F]
bases: {B: {parent: E, axis: 3, angle: x2}}
points: {P1: {coordinates: [x1, 0, 0]}, P2: {from: P1, base: B, coordinates: [L, 0, 0]}}
frames: {F1: {point: P1, base: B}}
bodies: {b1: {mass: 1, G: P1, base: E}, b2: {mass: 1, G: P2, base: B}}
effects:
"""

EVERY_EFFECT = HEADER + """\
  grav: {type: gravity, vector: [0, -9.81, 0]}
  field: {type: gravity, vector: [0, 0, -2*k], base: B}
  spring: {type: spring, point_a: O, point_b: P1, stiffness: k, rest_length: L, preload: -c}
  torsion: {type: torsion_spring, coordinate: x2, stiffness: k, rest_angle: pi/4}
  damper: {type: damper, point_a: P1, point_b: P2, damping: c}
  hinges: {type: joint_damping, coordinates: [x1, x2], damping: c}
  friction: {type: friction, coordinate: x1, coulomb: mu*9.81, viscous: c, static: 2*mu,
             stribeck_speed: 0.1, smoothing_speed: 0.01}
  drag: {type: drag, body: b2, point: P2, density: 1.2, drag_coefficient: 1, area: c/10}
  push: {type: action, body: b1, frame: F1, force: [F, 0, 0]}
"""


def error(snippet: str, header: str = HEADER) -> str:
    with pytest.raises(ModelError) as info:
        parse_model(header + snippet, source="m.yaml")
    return str(info.value)


def api_error(call) -> str:
    with pytest.raises(ModelError) as info:
        call()
    return str(info.value)


def api_model() -> Model:
    m = Model("m").add_coordinates("x1", "x2")
    m.add_parameters({"k": 10.0, "c": 0.5, "L": 1.0, "mu": 0.3}).add_input("F")
    m.add_base("B", parent="E", axis=3, angle="x2")
    m.add_point("P1", coordinates=["x1", 0, 0])
    m.add_point("P2", parent="P1", base="B", coordinates=["L", 0, 0])
    m.add_frame("F1", point="P1", base="B")
    m.add_body("b1", mass=1, G="P1", base="E").add_body("b2", mass=1, G="P2", base="B")
    return m


# -- the table that drives the loader matches the spec ------------------------------------

def test_every_effect_class_has_a_type_and_every_field_a_role():
    assert set(EFFECT_KINDS) == {cls.kind for cls in EFFECT_TYPES} | {"action"}
    for cls in EFFECT_TYPES:
        for f in dataclasses.fields(cls):
            assert f.name == "name" or f.name in EFFECT_FIELD_ROLES, (cls.kind, f.name)


# -- loading ---------------------------------------------------------------------------

def test_every_effect_type_loads_into_its_dataclass_in_declaration_order():
    spec = parse_model(EVERY_EFFECT)
    k, c, L, mu, F = (symbol(n) for n in ("k", "c", "L", "mu", "F"))
    r = sympy.Rational
    assert spec.effects == (
        GravityEffect("grav", (Z, -r(981, 100), Z), "E"),
        GravityEffect("field", (Z, Z, -2 * k), "B"),
        SpringEffect("spring", "O", "P1", k, L, -c),
        TorsionSpringEffect("torsion", "x2", k, sympy.pi / 4),
        DamperEffect("damper", "P1", "P2", c),
        JointDampingEffect("hinges", ("x1", "x2"), c),
        FrictionEffect("friction", "x1", r(981, 100) * mu, c, 2 * mu, r(1, 10), r(1, 100)),
        DragEffect("drag", "b2", "P2", r(6, 5), sympy.Integer(1), c / 10),
        ActionSpec("push", "b1", "P1", "B", (Z, Z, Z), (F, Z, Z)),
    )
    assert [e.kind for e in spec.effects] == [
        "gravity", "gravity", "spring", "torsion_spring", "damper", "joint_damping",
        "friction", "drag", "action"]
    assert spec.actions == () and spec.gravity is None


def test_omitted_optional_fields_take_the_dataclass_defaults():
    spec = parse_model(HEADER + """\
  g: {type: gravity, vector: [0, 0, -1]}
  s: {type: spring, point_a: O, point_b: P1, stiffness: k, rest_length: L, preload: ~}
  ts: {type: torsion_spring, coordinate: x1, stiffness: k}
  f: {type: friction, coordinate: x1, coulomb: mu}
""")
    g, s, t, f = spec.effects
    assert g.base == "E" and s.preload == 0 and t.rest_angle == 0
    assert (f.viscous, f.static, f.stribeck_speed, f.smoothing_speed) == (
        0, None, 1, sympy.Rational(1, 1000))


def test_action_effect_is_the_same_action_as_an_actions_entry():
    entry = "{body: b1, point: P2, base: B, torque: [0, 0, F*t], force: [x1_dot, 0, 0]}"
    as_action = parse_model(HEADER.replace("effects:\n", f"actions:\n  a: {entry}\n"))
    as_effect = parse_model(HEADER + f"  a: {{type: action, {entry[1:]}\n")
    assert as_effect.effects == as_action.actions
    assert as_effect.effects[0].kind == "action"


def test_effect_lines_point_at_their_keys():
    spec = parse_model(EVERY_EFFECT, source="m.yaml")
    assert spec.line_of("effects.spring.stiffness") == 12
    assert spec.line_of("effects.friction.smoothing_speed") == 17


def test_shipped_effect_models_load():
    chain = load_model(ROOT / "models" / "spring_chain.yaml")
    assert [e.name for e in chain.effects] == ["spring1", "spring2", "spring3",
                                               "damper1", "damper2", "damper3"]
    assert chain.effects[1] == SpringEffect("spring2", "P1", "P2", symbol("k"), symbol("L"))
    block = load_model(ROOT / "models" / "incline_block.yaml")
    m, g, alpha, mu = (symbol(n) for n in ("m", "g", "alpha", "mu"))
    assert block.effects == (FrictionEffect("friction", "s", mu * m * g * sympy.cos(alpha),
                                            smoothing_speed=symbol("v_s")),)


# -- round trips and the API -----------------------------------------------------------------

def test_effects_round_trip_through_yaml_and_from_spec():
    spec = parse_model(EVERY_EFFECT)
    text = spec_to_yaml(spec)
    assert parse_model(text) == spec
    assert Model.from_spec(spec).spec() == spec
    assert "  s: " not in text and "preload: -c" in text
    assert "  torsion: {type: torsion_spring, coordinate: x2, stiffness: k, rest_angle: pi/4}" \
        in text
    assert "  grav: {type: gravity, vector: [0, -981/100, 0]}" in text    # base E omitted


def test_top_level_gravity_and_actions_are_still_written_as_sections():
    spec = parse_model(HEADER.replace("effects:\n", "gravity: [0, -9.81, 0]\nactions:\n"
                                      "  a: {body: b1, point: O, base: E}\neffects:\n")
                       + "  d: {type: damper, point_a: O, point_b: P1, damping: c}\n")
    text = spec_to_yaml(spec)
    assert "\ngravity: [0, -981/100, 0]\nactions:\n  a: {body: b1" in text
    assert text.endswith("effects:\n  d: {type: damper, point_a: O, point_b: P1, damping: c}\n")
    assert parse_model(text) == spec


def test_api_builds_the_same_effects_as_the_yaml():
    m = api_model()
    m.add_effect("grav", "gravity", vector=[0, "-9.81", 0])
    m.add_effect("field", "gravity", vector=[0, 0, -2 * symbol("k")], base="B")
    m.add_effect("spring", "spring", point_a="O", point_b="P1", stiffness="k",
                 rest_length="L", preload="-c")
    m.add_effect("torsion", "torsion_spring", coordinate="x2", stiffness="k",
                 rest_angle=sympy.pi / 4)
    m.add_effect("damper", "damper", point_a="P1", point_b="P2", damping="c")
    m.add_effect("hinges", "joint_damping", coordinates=("x1", "x2"), damping="c")
    m.add_effect("friction", "friction", coordinate="x1", coulomb="mu*9.81", viscous="c",
                 static="2*mu", stribeck_speed=0.1, smoothing_speed="0.01")
    m.add_effect("drag", "drag", body="b2", point="P2", density=1.2, drag_coefficient=1,
                 area="c/10")
    m.add_effect("push", "action", body="b1", frame="F1", force=["F", 0, 0])
    assert m.spec() == parse_model(EVERY_EFFECT)
    assert parse_model(m.to_yaml()) == m.spec()


def test_a_failed_add_effect_leaves_the_model_unchanged():
    m = api_model()
    before = m.spec()
    with pytest.raises(ModelError):
        m.add_effect("s", "spring", point_a="O", point_b="P1", stiffness="-k", rest_length=1)
    assert m.spec() == before


# -- errors, with their exact messages ---------------------------------------------------------

def test_unknown_effect_type_suggests_the_closest():
    assert error("  s: {type: sprng, point_a: O, point_b: P1, stiffness: k, rest_length: L}\n"
                 ) == ("m.yaml:10: effects.s.type: unknown effect type 'sprng'; fix: did you "
                       "mean 'spring'? effect types: gravity, spring, torsion_spring, damper, "
                       "joint_damping, friction, drag, action")


def test_missing_effect_type():
    assert error("  d: {point_a: O, point_b: P1, damping: c}\n") == (
        "m.yaml:10: effects.d: missing required key 'type'; fix: add 'type: <effect type>', "
        "one of gravity, spring, torsion_spring, damper, joint_damping, friction, drag, action")


def test_effect_type_that_is_not_a_string():
    assert error("  d: {type: 3, point_a: O, point_b: P1, damping: c}\n") == (
        "m.yaml:10: effects.d.type: expected an effect type but got the number 3; "
        "fix: write one of gravity, spring, torsion_spring, damper, joint_damping, friction, "
        "drag, action")


def test_unknown_effect_key_suggests_the_closest():
    assert error("  ts: {type: torsion_spring, coordinate: x1, stifness: k}\n") == (
        "m.yaml:10: effects.ts.stifness: unknown key 'stifness' for a torsion_spring effect; "
        "fix: did you mean 'stiffness'? valid keys: type, coordinate, stiffness, rest_angle")


def test_missing_required_effect_key():
    assert error("  s: {type: spring, point_a: O, point_b: P1, stiffness: k}\n") == (
        "m.yaml:10: effects.s: missing required key 'rest_length'; fix: add 'rest_length'; "
        "a spring effect needs point_a, point_b, stiffness and rest_length")


def test_action_effect_takes_the_keys_of_actions():
    assert error("  a: {type: action, body: b1, point: O, base: E, moment: [0, 0, F]}\n") == (
        "m.yaml:10: effects.a.moment: unknown key 'moment' for an action effect; fix: valid "
        "keys: type, body, point, base, frame, torque, force, vector")
    assert error("  a: {type: action, body: b1, force: [F, 0, 0]}\n") == (
        "m.yaml:10: effects.a: missing required key 'point' (or 'frame'); "
        "fix: add 'point' and 'base', or 'frame'")


@pytest.mark.parametrize("snippet, expected", [
    ("  s: {type: spring, point_a: O, point_b: P1, stiffness: -k, rest_length: L}\n",
     "m.yaml:10: effects.s.stiffness: stiffness of spring 's' is negative: -k = -10.0 with "
     "the default parameters; fix: give a stiffness >= 0"),
    ("  s: {type: spring, point_a: O, point_b: P1, stiffness: k, rest_length: c - L}\n",
     "m.yaml:10: effects.s.rest_length: rest_length of spring 's' is negative: -L + c = -0.5 "
     "with the default parameters; fix: give a rest_length >= 0"),
    ("  j: {type: joint_damping, coordinates: [x1], damping: -0.1}\n",
     "m.yaml:10: effects.j.damping: damping of joint_damping 'j' is negative: -1/10 = -0.1 "
     "with the default parameters; fix: give a damping >= 0"),
    ("  f: {type: friction, coordinate: x1, coulomb: mu - 1}\n",
     "m.yaml:10: effects.f.coulomb: coulomb of friction 'f' is negative: mu - 1 = -0.7 with "
     "the default parameters; fix: give a coulomb >= 0"),
    ("  f: {type: friction, coordinate: x1, coulomb: mu, stribeck_speed: 0}\n",
     "m.yaml:10: effects.f.stribeck_speed: stribeck_speed of friction 'f' is not positive: "
     "0 = 0.0 with the default parameters; fix: give a stribeck_speed > 0"),
    ("  d: {type: drag, body: b1, point: P1, density: -1.2, drag_coefficient: 1, area: 1}\n",
     "m.yaml:10: effects.d.density: density of drag 'd' is negative: -6/5 = -1.2 with the "
     "default parameters; fix: give a density >= 0"),
])
def test_negative_coefficients_at_the_defaults(snippet, expected):
    assert error(snippet) == expected


def test_smoothing_speed_must_be_positive():
    assert error("  f: {type: friction, coordinate: x1, coulomb: mu, smoothing_speed: 0}\n"
                 ) == ("m.yaml:10: effects.f.smoothing_speed: smoothing_speed of friction 'f' "
                       "is not positive: 0 = 0.0 with the default parameters; fix: give a "
                       "smoothing_speed > 0 (the speed over which friction changes sign: "
                       "tanh(v/smoothing_speed); e.g. 0.001)")


def test_coefficient_that_is_not_real_at_the_defaults():
    assert error("  ts: {type: torsion_spring, coordinate: x1, stiffness: sqrt(c - L)}\n") == (
        "m.yaml:10: effects.ts.stiffness: stiffness of torsion_spring 'ts' is not a real number "
        "with the default parameters: sqrt(-L + c); fix: give a stiffness >= 0")


def test_coefficients_may_only_use_parameters():
    assert error("  j: {type: joint_damping, coordinates: [x1], damping: c*x1}\n") == (
        "m.yaml:10: effects.j.damping: coordinate 'x1' is not allowed in expression 'c*x1'; "
        "fix: use only parameters here (effect coefficients, lengths and speeds are constant)")
    assert error("  j: {type: joint_damping, coordinates: [x1], damping: cc}\n") == (
        "m.yaml:10: effects.j.damping: undefined name 'cc' in expression 'cc'; fix: did you "
        "mean 'c'? Otherwise declare 'cc' under 'parameters'; only parameters may be used here")


def test_gravity_effect_vector_follows_the_gravity_rule():
    assert error("  g: {type: gravity, vector: [0, 0, F]}\n") == (
        "m.yaml:10: effects.g.vector[2]: input 'F' is not allowed in expression 'F'; fix: use "
        "only parameters and t here (gravity is a uniform field; use an action for forces "
        "that depend on the state or on inputs)")
    assert error("  g: {type: gravity, vector: [0, -9.81]}\n") == (
        "m.yaml:10: effects.g.vector: expected 3 components but got 2; fix: write [gx, gy, gz] "
        "(components in the effect's base)")


@pytest.mark.parametrize("snippet, expected", [
    ("  s: {type: spring, point_a: O, point_b: P3, stiffness: k, rest_length: L}\n",
     "m.yaml:10: effects.s.point_b: unknown point 'P3'; fix: declare 'P3' under 'points' "
     "(known points: O, P1, P2)"),
    ("  ts: {type: torsion_spring, coordinate: q1, stiffness: k}\n",
     "m.yaml:10: effects.ts.coordinate: unknown coordinate 'q1'; fix: declare 'q1' under "
     "'coordinates' (known coordinates: x1, x2)"),
    ("  ts: {type: torsion_spring, coordinate: b1, stiffness: k}\n",
     "m.yaml:10: effects.ts.coordinate: 'b1' is a body, not a coordinate; fix: name a "
     "coordinate here (known coordinates: x1, x2)"),
    ("  j: {type: joint_damping, coordinates: [x1, x3], damping: c}\n",
     "m.yaml:10: effects.j.coordinates[1]: unknown coordinate 'x3'; fix: declare 'x3' under "
     "'coordinates' (known coordinates: x1, x2)"),
    ("  d: {type: drag, body: bb1, point: P1, density: 1, drag_coefficient: 1, area: 1}\n",
     "m.yaml:10: effects.d.body: unknown body 'bb1'; fix: did you mean 'b1'? Otherwise "
     "declare 'bb1' under 'bodies'"),
    ("  g: {type: gravity, vector: [0, 0, -1], base: P1}\n",
     "m.yaml:10: effects.g.base: 'P1' is a point, not a base; fix: name a base here "
     "(known bases: E, B)"),
    ("  a: {type: action, body: b1, frame: F2}\n",
     "m.yaml:10: effects.a.frame: unknown frame 'F2'; fix: declare 'F2' under 'frames' "
     "(known frames: F1)"),
])
def test_effect_references_are_resolved(snippet, expected):
    assert error(snippet) == expected


def test_spring_and_damper_need_two_different_points():
    assert error("  d: {type: damper, point_a: P1, point_b: P1, damping: c}\n") == (
        "m.yaml:10: effects.d.point_b: damper 'd' joins point 'P1' to itself; fix: give two "
        "different points (a damper acts along the line between them)")


def test_joint_damping_coordinates_are_a_list_without_repeats():
    assert error("  j: {type: joint_damping, coordinates: x1, damping: c}\n") == (
        "m.yaml:10: effects.j.coordinates: expected a list of one or more coordinate names "
        "but got the string 'x1'; fix: write e.g. [q1, q2]")
    assert error("  j: {type: joint_damping, coordinates: [], damping: c}\n") == (
        "m.yaml:10: effects.j.coordinates: expected a list of one or more coordinate names "
        "but got a list of 0 items; fix: write e.g. [q1, q2]")
    assert error("  j: {type: joint_damping, coordinates: [x2, x2], damping: c}\n") == (
        "m.yaml:10: effects.j.coordinates[1]: coordinate 'x2' is listed twice; "
        "fix: list each coordinate once")


def test_effect_names_share_the_namespace():
    assert error("  k: {type: joint_damping, coordinates: [x1], damping: c}\n") == (
        "m.yaml:10: effects.k: duplicate name 'k': already declared as a parameter at "
        "parameters.k (line 3); fix: rename one of them; coordinates, parameters, inputs, "
        "bases, points, frames, bodies, actions and effects share one namespace")


def test_no_effect_or_action_may_be_named_gravity_beside_top_level_gravity():
    header = HEADER.replace("effects:\n", "gravity: [0, -9.81, 0]\neffects:\n")
    assert error("  gravity: {type: gravity, vector: [0, 0, -1]}\n", header) == (
        "m.yaml:11: effects.gravity: an effect is named 'gravity', the name of the top-level "
        "gravity; fix: rename the effect, or remove the top-level 'gravity:' and declare it "
        "as an effect of type gravity")
    alone = parse_model(HEADER + "  gravity: {type: gravity, vector: [0, 0, -1]}\n")
    assert alone.effects[0].name == "gravity" and alone.gravity is None


def test_effects_section_must_be_a_mapping_of_mappings():
    assert error(" [a, b]\n", HEADER.rstrip("\n")) == (
        "m.yaml:9: effects: expected a mapping of effect names to definitions but got a list "
        "of 2 items; fix: write one entry per line, e.g. 'spring1: {type: spring, point_a: "
        "A, point_b: P1, stiffness: k, rest_length: L0}'")
    assert error("  s: spring\n") == (
        "m.yaml:10: effects.s: expected a mapping but got the string 'spring'; fix: write it "
        "like 'spring1: {type: spring, point_a: A, point_b: P1, stiffness: k, "
        "rest_length: L0}'")


def test_api_errors_name_the_api_and_the_key():
    assert api_error(lambda: api_model().add_effect("s", "spring", point_a="O",
                                                    point_b="P1", stiffness="k")) == (
        "<api>: effects.s: missing required key 'rest_length'; fix: add 'rest_length'; "
        "a spring effect needs point_a, point_b, stiffness and rest_length")
    m = api_model().add_effect("ts", "torsion_spring", coordinate="x9", stiffness="k")
    assert api_error(m.spec) == (
        "<api>: effects.ts.coordinate: unknown coordinate 'x9'; fix: declare 'x9' under "
        "'coordinates' (known coordinates: x1, x2)")
