"""Loading models: shipped YAML files, the Python API, round trips, ordering, frames."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy

from modelgen.errors import ModelError
from modelgen.model.chains import spatial_chain
from modelgen.model.api import Model, load_model, parse_model, spec_to_yaml
from modelgen.model.spec import (TIME, ActionSpec, BaseSpec, BodySpec, FrameSpec, ModelSpec,
                           PointSpec, symbol)

ROOT = Path(__file__).resolve().parent.parent
MODEL_FILES = sorted((ROOT / "models").glob("*.yaml"))
SHIPPED = ["arm7", "cart_pole", "double_pendulum", "four_bar", "furuta_pendulum", "heavy_top",
           "incline_block", "rolling_disc", "simple_pendulum", "slider_crank",
           "spherical_pendulum", "spring_chain", "tennis_racket", "torque_free_body",
           "whipple_bicycle"]
Z = sympy.Integer(0)


def S(*names):
    return [symbol(n) for n in names]


# -- shipped models ------------------------------------------------------------------

def test_every_required_model_file_is_shipped():
    assert sorted(path.stem for path in MODEL_FILES) == sorted(SHIPPED)


@pytest.mark.parametrize("path", MODEL_FILES, ids=lambda p: p.stem)
def test_shipped_model_loads_and_round_trips_through_yaml(path):
    spec = load_model(path)
    assert spec.name == path.stem
    assert spec.source == str(path)
    assert parse_model(spec_to_yaml(spec)) == spec
    assert Model.from_spec(spec).spec() == spec
    assert Model.from_yaml(path).to_yaml() == spec_to_yaml(spec)


@pytest.mark.parametrize("path", MODEL_FILES, ids=lambda p: p.stem)
def test_shipped_model_uses_only_declared_symbols(path):
    spec = load_model(path)
    declared = set(S(*spec.coordinates, *spec.speeds, *spec.parameter_names, *spec.inputs))
    declared.add(TIME)
    assert spec.free_symbols() <= declared
    assert any(True for _ in spec.expressions())


@pytest.mark.parametrize("path", MODEL_FILES, ids=lambda p: p.stem)
def test_shipped_model_is_in_topological_order(path):
    spec = load_model(path)
    seen_bases, seen_points = {"E"}, {"O"}
    for b in spec.bases:
        assert b.parent in seen_bases
        seen_bases.add(b.name)
    for p in spec.points:
        assert p.parent in seen_points and p.base in seen_bases
        seen_points.add(p.name)


def test_double_pendulum_matches_a_hand_built_spec():
    q1, q2, m1, m2, l1, l2, g, T1 = S("q1", "q2", "m1", "m2", "l1", "l2", "g", "T1")
    rod1 = ((Z, Z, Z), (Z, m1 * l1**2 / 12, Z), (Z, Z, m1 * l1**2 / 12))
    rod2 = ((Z, Z, Z), (Z, m2 * l2**2 / 12, Z), (Z, Z, m2 * l2**2 / 12))
    expected = ModelSpec(
        name="double_pendulum",
        description="Planar double pendulum of two uniform rods, hinged at O.",
        coordinates=("q1", "q2"),
        parameters=(("m1", 1.0), ("m2", 1.0), ("l1", 1.0), ("l2", 1.0), ("g", 9.81)),
        inputs=("T1",),
        bases=(BaseSpec("B1", "E", 3, q1), BaseSpec("B2", "B1", 3, q2)),
        points=(PointSpec("P1", "O", "B1", (l1, Z, Z)),
                PointSpec("G1", "O", "B1", (l1 / 2, Z, Z)),
                PointSpec("G2", "P1", "B2", (l2 / 2, Z, Z)),
                PointSpec("A", "O", "E", (Z, sympy.Integer(-3), Z))),
        frames=(FrameSpec("F2", "P1", "B2"),),
        bodies=(BodySpec("rod1", m1, "G1", "B1", rod1), BodySpec("rod2", m2, "G2", "B2", rod2)),
        gravity=(Z, -g, Z),
        actions=(ActionSpec("motor", "rod1", "O", "B1", (Z, Z, T1), (Z, Z, Z)),),
        units=(("q1", "rad"), ("q2", "rad"), ("m1", "kg"), ("m2", "kg"), ("l1", "m"),
               ("l2", "m"), ("g", "m/s2"), ("T1", "N.m")),
    )
    assert load_model(ROOT / "models" / "double_pendulum.yaml") == expected


def test_double_pendulum_lines_are_one_based_and_point_at_keys():
    spec = load_model(ROOT / "models" / "double_pendulum.yaml")
    assert spec.line_of("name") == 1
    assert spec.line_of("bases.B2.parent") == 8
    assert spec.line_of("points.A") == 13
    assert spec.line_of("bodies.rod2.inertia") == 18
    assert spec.line_of("actions.motor.torque[2]") == 21
    assert spec.line_of("nothing.here") is None


def test_api_builds_the_same_spec_as_the_double_pendulum_yaml():
    m = Model("double_pendulum",
              description="Planar double pendulum of two uniform rods, hinged at O.")
    m.add_coordinates("q1", "q2")
    for name in ("m1", "m2", "l1", "l2"):
        m.add_parameter(name, 1.0)
    m.add_parameter("g", 9.81)
    m.add_input("T1")
    m.add_base("B1", parent="E", axis=3, angle="q1")
    m.add_base("B2", parent="B1", axis=3, angle=symbol("q2"))
    m.add_point("P1", parent="O", base="B1", coordinates=["l1", 0, 0])
    m.add_point("G1", parent="O", base="B1", coordinates=[symbol("l1") / 2, 0, 0])
    m.add_point("G2", parent="P1", base="B2", coordinates=["l2/2", 0.0, 0])
    m.add_point("A", coordinates=[0, -3, 0])
    m.add_frame("F2", point="P1", base="B2")
    m.add_body("rod1", mass="m1", G="G1", base="B1", inertia=[0, "m1*l1**2/12", "m1*l1**2/12"])
    m.add_body("rod2", mass="m2", G="G2", base="B2",
               inertia=[[0, 0, 0], [0, "m2*l2**2/12", 0], [0, 0, "m2*l2**2/12"]])
    m.set_gravity([0, "-g", 0])
    m.add_action("motor", body="rod1", point="O", base="B1", torque=[0, 0, "T1"],
                 force=[0, 0, 0])
    m.set_units({"q1": "rad", "q2": "rad", "m1": "kg", "m2": "kg", "l1": "m", "l2": "m",
                 "g": "m/s2", "T1": "N.m"})
    from_yaml = load_model(ROOT / "models" / "double_pendulum.yaml")
    assert m.spec() == from_yaml
    assert parse_model(m.to_yaml()) == m.spec()
    assert m.spec().source is None and m.spec().lines == ()


# -- ordering and resolution -----------------------------------------------------------

ORDER_YAML = """
name: order
coordinates: [q1, q2, q3]
bases:
  B3: {parent: B2, axis: 1, angle: q3}
  C1: {parent: E, axis: 2, angle: q1}
  B2: {parent: B1, axis: 3, angle: q2}
  B1: {parent: E, axis: 3, angle: q1}
points:
  P3: {from: P2, base: B3, coordinates: [1, 0, 0]}
  P2: {frame: F1, coordinates: [1, 0, 0]}
  Q:  {coordinates: [0, 1, 0]}
  P1: {from: O, base: B1, coordinates: [1, 0, 0]}
frames:
  F1: {point: P1, base: B2}
"""


def test_bases_and_points_are_sorted_parents_first_keeping_declaration_order():
    spec = parse_model(ORDER_YAML)
    assert [b.name for b in spec.bases] == ["C1", "B1", "B2", "B3"]
    assert [p.name for p in spec.points] == ["Q", "P1", "P2", "P3"]


def test_sorted_spec_written_parents_first_reads_back_identically():
    spec = parse_model(ORDER_YAML)
    again = parse_model(spec_to_yaml(spec))
    assert again == spec
    assert [b.name for b in again.bases] == [b.name for b in spec.bases]


def test_a_point_given_a_frame_gets_the_frames_point_and_base():
    spec = parse_model(ORDER_YAML)
    p2 = next(p for p in spec.points if p.name == "P2")
    assert (p2.parent, p2.base) == ("P1", "B2")


def test_an_action_given_a_frame_gets_the_frames_point_and_base():
    spec = parse_model("""
name: m
inputs: [F]
frames: {F1: {point: P, base: E}}
points: {P: {coordinates: [1, 2, 3]}}
bodies: {b: {mass: 1, G: P, base: E}}
actions: {push: {body: b, frame: F1, force: [F, 0, 0]}}
""")
    assert spec.actions == (ActionSpec("push", "b", "P", "E", (Z, Z, Z), (symbol("F"), Z, Z)),)


def test_action_vector_is_torque_then_force():
    text = """
name: m
coordinates: [x]
inputs: [u]
bodies: {b: {mass: 1, G: O, base: E}}
actions: {a: {body: b, point: O, base: E, %s}}
"""
    with_vector = parse_model(text % "vector: [1, 2, u, x_dot, 0, t]")
    with_pair = parse_model(text % "torque: [1, 2, u], force: [x_dot, 0, t]")
    assert with_vector == with_pair
    assert with_vector.actions[0].force == (symbol("x_dot"), Z, TIME)


def test_omitted_torque_and_force_default_to_zeros():
    spec = parse_model("""
name: m
bodies: {b: {mass: 1, G: O, base: E}}
actions: {a: {body: b, point: O, base: E}}
""")
    assert spec.actions[0].torque == (Z, Z, Z) and spec.actions[0].force == (Z, Z, Z)


# -- values -------------------------------------------------------------------------

def test_inertia_forms_principal_full_and_omitted():
    spec = parse_model("""
name: m
parameters: {I: 2.0, J: 1.5}
bodies:
  principal: {mass: 1, G: O, base: E, inertia: [I, J, J]}
  full: {mass: 1, G: O, base: E, inertia: [[I, 0.1, 0], [0.1, J, 0], [0, 0, J]]}
  particle: {mass: 1, G: O, base: E}
""")
    I, J = S("I", "J")
    tenth = sympy.Rational(1, 10)
    assert spec.bodies[0].inertia == ((I, Z, Z), (Z, J, Z), (Z, Z, J))
    assert spec.bodies[1].inertia == ((I, tenth, Z), (tenth, J, Z), (Z, Z, J))
    assert spec.bodies[2].inertia == ((Z, Z, Z),) * 3


def test_inertia_equal_after_expansion_is_accepted_and_mirrored():
    spec = parse_model("""
name: m
parameters: {a: 1.0, b: 1.0}
bodies:
  b1: {mass: 1, G: O, base: E, inertia: [[2, a*(a+b)/10, 0], [(a**2+a*b)/10, 2, 0], [0, 0, 2]]}
""")
    inertia = spec.bodies[0].inertia
    assert inertia[0][1] == inertia[1][0]
    assert sympy.expand(inertia[0][1] - (symbol("a")**2 + symbol("a") * symbol("b")) / 10) == 0


def test_parameters_keep_order_and_become_floats():
    spec = parse_model('name: m\nparameters: {z: 3, a: 0.5, k: "1e5", n: -2.5}\n')
    assert spec.parameters == (("z", 3.0), ("a", 0.5), ("k", 100000.0), ("n", -2.5))
    assert all(isinstance(v, float) for v in spec.parameter_defaults)


def test_decimals_in_expressions_are_exact():
    spec = parse_model("name: m\npoints: {P: {coordinates: [0.1, 9.81, '1e-3']}}\n")
    assert spec.points[0].coordinates == (sympy.Rational(1, 10), sympy.Rational(981, 100),
                                          sympy.Rational(1, 1000))


def test_gravity_is_none_when_absent_and_null_sections_are_empty():
    spec = parse_model("name: m\ncoordinates:\ninputs: ~\nbases:\ngravity:\n")
    assert spec.gravity is None and spec.coordinates == () and spec.bases == ()


def test_time_and_speeds_are_allowed_where_documented():
    spec = parse_model("""
name: m
coordinates: [q]
parameters: {w: 2.0}
inputs: [u]
bases: {B: {parent: E, axis: 3, angle: q}}
gravity: [0, 0, -9.81*cos(t)]
bodies: {b: {mass: 1, G: O, base: B}}
actions: {a: {body: b, point: O, base: B, torque: [0, 0, -w*q_dot + u*t]}}
""")
    q, w, u, q_dot = S("q", "w", "u", "q_dot")
    assert spec.gravity[2] == -sympy.Rational(981, 100) * sympy.cos(TIME)
    assert spec.actions[0].torque[2] == -w * q_dot + u * TIME


@pytest.mark.parametrize("key, entry", [
    ("bases.B.angle", "bases: {B: {parent: E, axis: 3, angle: q + sin(w*t)}}"),
    ("points.P.coordinates[0]", "points: {P: {from: O, base: E, coordinates: [t, 0, 0]}}")])
def test_time_in_a_position_is_refused_where_it_is_read(key, entry):
    """Prescribed motion is not supported (A, h, the energies and the poses take no
    time): refused by the reader at its line, not later by the derivation."""
    text = f"name: m\ncoordinates: [q]\nparameters: {{w: 2.0}}\n{entry}\n"
    with pytest.raises(ModelError) as err:
        parse_model(text, source="m.yaml")
    e = err.value
    assert (e.file, e.line, e.key) == ("m.yaml", 4, key)
    assert "time 't' is not allowed" in str(e) and "drive it with an action" in e.fix


def test_time_in_a_hand_built_spec_is_refused_by_the_derivation():
    """A ModelSpec built in Python skips the reader's rule: the derivation refuses t
    in a base angle with the same fix."""
    from modelgen.derive.kinematics import derive_kinematics
    (q,) = S("q")
    spec = ModelSpec("m", coordinates=("q",),
                     bases=(BaseSpec("B", "E", 3, q + sympy.sin(TIME)),))
    with pytest.raises(ModelError, match="prescribed motion") as err:
        derive_kinematics(spec)
    assert err.value.key == "bases.B.angle"


def test_names_A_and_single_letters_are_legal_user_names():
    spec = parse_model("name: m\ncoordinates: [x, y]\nparameters: {A: 1, C: 2, e: 3}\n")
    assert spec.parameter_names == ("A", "C", "e")


def test_description_with_special_characters_round_trips():
    m = Model("m", description='line one: "quoted", #hash\nline two \u00e9')
    assert parse_model(m.to_yaml()).description == m.description


def test_names_yaml_would_misread_are_quoted_when_written():
    m = Model("m").add_coordinates("on", "yes", "null1").add_parameter("off", 1.0)
    m.add_point("P", coordinates=["on", "off", 0])
    assert parse_model(m.to_yaml()) == m.spec()


def test_expressions_with_commas_and_parentheses_round_trip_through_yaml():
    m = Model("m").add_coordinate("q").add_input("u")
    m.add_point("P", coordinates=["atan2(q, 1)", "-(q + 1)**2", "(q + 1)*(q - 1)/3"])
    m.add_body("b", mass=1, G="P", base="E")
    m.add_action("a", body="b", point="P", base="E",
                 torque=["-abs(q_dot)*sign(q_dot)", "exp(-t/2)", "-1*(u + q)/q_dot"])
    assert parse_model(m.to_yaml()) == m.spec()


def test_parameter_defaults_in_exponent_notation_round_trip():
    m = Model("m").add_parameters({"tiny": 1e-05, "huge": 1e20, "odd": 0.1 + 0.2})
    assert parse_model(m.to_yaml()).parameters == m.spec().parameters


# -- the Python API ------------------------------------------------------------------

def test_api_accepts_forward_references_checked_by_spec():
    m = Model("m").add_coordinate("q")
    m.add_point("P", parent="O", base="B", coordinates=[1, 0, 0])   # B not yet declared
    m.add_base("B", parent="E", axis=1, angle="q")
    assert m.spec().points[0].base == "B"


def test_api_methods_chain_and_from_spec_copies():
    spec = (Model("m").add_coordinate("q").add_parameter("L", 2.0)
            .add_base("B", parent="E", axis=2, angle="q")
            .add_point("P", parent="O", base="B", coordinates=[0, 0, "-L"])
            .add_body("bob", mass=1, G="P", base="B").spec())
    assert Model.from_spec(spec).spec() == spec


def test_api_accepts_numpy_and_sympy_matrices_for_inertia():
    a = Model("m").add_body("b", mass=1, G="O", base="E", inertia=np.eye(3) * 0.5).spec()
    b = Model("m").add_body("b", mass=1, G="O", base="E",
                            inertia=sympy.Matrix.diag(0.5, 0.5, 0.5)).spec()
    assert a == b
    assert a.bodies[0].inertia[0][0] == sympy.Rational(1, 2)


# -- the spatial chain -------------------------------------------------------------------

def test_spatial_chain_follows_its_documented_definition():
    spec = spatial_chain(4).spec()
    assert spec.name == "spatial_chain_4"
    assert spec.coordinates == ("q1", "q2", "q3", "q4")
    assert spec.parameters == (("m1", 1.0), ("m2", 1.0), ("m3", 1.0), ("m4", 1.0),
                               ("l1", 0.5), ("l2", 0.5), ("l3", 0.5), ("l4", 0.5),
                               ("r", 0.02), ("g", 9.81))
    assert [(b.name, b.parent, b.axis, b.angle) for b in spec.bases] == [
        ("B1", "E", 3, symbol("q1")), ("B2", "B1", 2, symbol("q2")),
        ("B3", "B2", 3, symbol("q3")), ("B4", "B3", 2, symbol("q4"))]
    points = {p.name: p for p in spec.points}
    l3, m3, r = S("l3", "m3", "r")
    assert points["P3"] == PointSpec("P3", "P2", "B3", (l3, Z, Z))
    assert points["G3"] == PointSpec("G3", "P2", "B3", (l3 / 2, Z, Z))
    assert points["G1"].parent == "O"
    rod3 = spec.bodies[2]
    assert (rod3.name, rod3.mass, rod3.G, rod3.base) == ("rod3", m3, "G3", "B3")
    transverse = m3 * l3**2 / 12 + m3 * r**2 / 4
    assert rod3.inertia == ((m3 * r**2 / 2, Z, Z), (Z, transverse, Z), (Z, Z, transverse))
    assert spec.gravity == (Z, Z, -symbol("g"))


def test_spatial_chain_of_50_links_round_trips():
    spec = spatial_chain(50).spec()
    assert len(spec.bodies) == 50 and len(spec.points) == 100
    assert parse_model(spec_to_yaml(spec)) == spec


# -- physical validity of the shipped models --------------------------------------------

def _numeric_inertia(spec: ModelSpec, body: BodySpec) -> np.ndarray:
    defaults = {symbol(n): v for n, v in spec.parameters}
    return np.array([[float(e.subs(defaults)) for e in row] for row in body.inertia])


def test_arm7_has_seven_alternating_joints_and_full_valid_inertias():
    spec = load_model(ROOT / "models" / "arm7.yaml")
    assert [b.axis for b in spec.bases] == [3, 2, 3, 2, 3, 2, 3]
    assert [b.parent for b in spec.bases] == ["E", "B1", "B2", "B3", "B4", "B5", "B6"]
    assert len(spec.bodies) == 7
    for body in spec.bodies:
        inertia = _numeric_inertia(spec, body)
        assert np.array_equal(inertia, inertia.T)
        assert np.all(inertia[~np.eye(3, dtype=bool)] != 0), body.name   # products of inertia
        moments = np.linalg.eigvalsh(inertia)
        assert moments[0] > 0, body.name
        assert moments[0] + moments[1] >= moments[2], body.name
        centre = next(p for p in spec.points if p.name == body.G)
        assert any(c != 0 for c in centre.coordinates), body.name   # CoM off the joint
    offsets = {p.name: p.coordinates for p in spec.points}
    assert sum(sum(c != 0 for c in offsets[f"J{i}"]) >= 2 for i in range(2, 8)) >= 2


def test_arm7_motor_pairs_cancel_on_the_parent_link():
    spec = load_model(ROOT / "models" / "arm7.yaml")
    actions = {a.name: a for a in spec.actions}
    for i in range(2, 8):
        motor, reaction = actions[f"motor{i}"], actions[f"motor{i}_reaction"]
        assert (motor.body, reaction.body) == (f"link{i}", f"link{i - 1}")
        assert motor.base == reaction.base
        assert tuple(-c for c in motor.torque) == reaction.torque


@pytest.mark.parametrize("path", MODEL_FILES, ids=lambda p: p.stem)
def test_shipped_inertias_are_physical_at_default_parameters(path):
    spec = load_model(path)
    for body in spec.bodies:
        moments = np.linalg.eigvalsh(_numeric_inertia(spec, body))
        assert moments[0] >= -1e-12
        assert moments[0] + moments[1] >= moments[2] - 1e-12


def test_python_api_spells_the_yaml_keys_and_keeps_the_old_names():
    """The Python API takes what the YAML takes: ``from_=`` for the key ``from``, lists
    for the list sections and mappings or keywords for the maps; the old spellings
    (``parent=``, ``origin=``, varargs) build the same model."""
    yaml_spec = parse_model("""
name: m
coordinates: [q1, q2]
inputs: [T1, T2]
parameters: {L: 1.0, m: 2.0}
bases: {B1: {parent: E, axis: 3, angle: q1}}
points:
  P: {from: O, base: B1, coordinates: [L, 0, 0]}
  Q: {from: P, base: E, coordinates: [0, q2, 0]}
bodies: {b: {mass: m, G: Q, base: B1}}
joints: {J: {type: free, parent: E, base: B2, from: P, point: R}}
""")

    def build(new: bool) -> Model:
        m = Model("m")
        if new:
            m.add_coordinates(["q1", "q2"]).add_inputs(["T1", "T2"]).add_parameters(L=1.0, m=2.0)
        else:
            m.add_coordinates("q1", "q2").add_inputs("T1", "T2").add_parameters({"L": 1.0,
                                                                                 "m": 2.0})
        m.add_joint("J", "free", parent="E", base="B2", point="R",      # the YAML's order
                    **({"from_": "P"} if new else {"origin": "P"}))
        m.add_base("B1", parent="E", axis=3, angle="q1")
        where = (lambda p: {"from_": p}) if new else (lambda p: {"parent": p})
        m.add_point("P", base="B1", coordinates=["L", 0, 0], **where("O"))
        m.add_point("Q", base="E", coordinates=[0, "q2", 0], **where("P"))
        m.add_body("b", mass="m", G="Q", base="B1")
        return m
    assert build(new=True).spec() == yaml_spec == build(new=False).spec()


def test_python_api_refuses_two_spellings_that_disagree():
    from modelgen.errors import ModelError
    m = Model("m").add_parameters({"a": 1.0})
    with pytest.raises(ModelError, match="points.P: both from_='O' and parent='E1'"):
        m.add_point("P", from_="O", parent="E1", base="E", coordinates=[0, 0, 0])
    with pytest.raises(ModelError, match="parameters a given both in the mapping and as"):
        Model("m").add_parameters({"a": 1.0}, a=2.0)
    assert m.spec().parameters == (("a", 1.0),)
