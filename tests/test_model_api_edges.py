"""The model stage's edges found by an audit of the Python API and the importers: names
from a robot file cannot inject YAML through the import's comments, the model name
``mg`` is refused, a model built in any order reads back from its YAML to the same
spec and C, API inputs give ModelErrors (never a bare Python error), what is accepted
can be written and read back, and the acceleration symbols of the symbolic queries
are reserved names."""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import sympy

import modelgen
from modelgen.cli import main
from modelgen.derive.queries import Mechanism
from modelgen.errors import ModelError
from modelgen.model.api import Model, load_model, parse_model
from modelgen.model.mjcf import import_mjcf_text, mjcf_to_yaml
from modelgen.model.spec import symbol
from modelgen.model.urdf import import_urdf_text, urdf_to_yaml

#: every character YAML takes as a line break, and others that XML 1.0 can carry
XML_BREAKS = ["\n", "\r", "\r\n", "\x85", "\u2028", "\u2029", "\t", "\x9b", "\ufeff"]
#: and the controls a file name may hold besides
BREAKS = XML_BREAKS + ["\x0b", "\x0c", "\x1b", "\x7f", "\udcff"]

INJECTED = "armature: {j1: 5.0}"


def _xml_escaped(text: str) -> str:
    """``text`` with every non-ASCII or control character as an XML character reference."""
    return "".join(c if " " <= c < "\x7f" else f"&#{ord(c)};" for c in text)


def _urdf(joint_name: str) -> str:
    return f"""<?xml version="1.0"?>
<robot name="r">
  <link name="world"/>
  <link name="base"><inertial><mass value="1"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="arm"><inertial><origin xyz="0.5 0 0"/><mass value="1"/>
    <inertia ixx="0.01" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="{_xml_escaped(joint_name)}" type="floating">
    <parent link="world"/><child link="base"/></joint>
  <joint name="j1" type="revolute"><parent link="base"/><child link="arm"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>
"""


def _assert_only_comments_before(text: str) -> None:
    head = text[:text.index("\nname: ")]
    assert all(line.startswith("#") for line in head.splitlines()), head


@pytest.mark.parametrize("brk", XML_BREAKS, ids=repr)
def test_a_line_break_in_a_urdf_joint_name_stays_inside_the_imports_comment(brk):
    """A floating root joint imported fixed is named in a '# Note:' line; a line break
    in its name used to end the comment and make the rest of the name YAML."""
    name = f"f{brk}{INJECTED}{brk}#"
    imported = import_urdf_text(_urdf(name), "fl.urdf", fix_floating_root=True)
    text = urdf_to_yaml(imported)
    _assert_only_comments_before(text)
    spec = parse_model(text)
    assert spec == imported.model.spec()
    assert spec.armature == ()
    assert all(note.isprintable() for note in imported.notes)


@pytest.mark.parametrize("brk", BREAKS, ids=repr)
def test_a_line_break_in_the_source_file_name_stays_inside_the_imports_comment(brk):
    source = f"r{brk}{INJECTED}{brk}#.urdf"
    imported = import_urdf_text(_urdf("f"), source, fix_floating_root=True)
    text = urdf_to_yaml(imported)
    _assert_only_comments_before(text)
    assert parse_model(text) == imported.model.spec()
    assert parse_model(text).armature == ()


MJCF = """<mujoco>
  <worldbody>
    <body name="arm">
      <joint name="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.05" mass="1"/>
      <body name="arm2" pos="0.5 0 0">
        <joint name="hinge2" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.05" mass="1"/>
      </body>
    </body>
  </worldbody>
  <equality>
    <joint name="{name}" joint1="hinge" joint2="hinge2" active="false"/>
  </equality>
</mujoco>
"""


@pytest.mark.parametrize("brk", ["\n", "\r", "\x85", "\u2028", "\u2029"], ids=repr)
def test_a_line_break_in_an_mjcf_name_stays_inside_the_imports_comment(brk, tmp_path,
                                                                       monkeypatch):
    monkeypatch.chdir(tmp_path)          # MuJoCo may write its log into the cwd
    name = _xml_escaped(f"x{brk}armature: {{hinge: 1000.0}}{brk}#")
    imported = import_mjcf_text(MJCF.format(name=name), "eq.xml")
    text = mjcf_to_yaml(imported)
    _assert_only_comments_before(text)
    spec = parse_model(text)
    assert spec == imported.model.spec()
    assert spec.armature == ()


def test_modelgen_import_writes_and_reports_the_notes_on_one_line_each(tmp_path, capsys):
    """The whole command: the file read back equals the direct import, and no note
    printed on the terminal spills onto a line of its own."""
    urdf = tmp_path / "fl.urdf"
    urdf.write_text(_urdf(f"f\n{INJECTED}\n#"))
    out = tmp_path / "fl.yaml"
    assert main(["import", str(urdf), "--fix-floating-root", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert not any(line.startswith("armature") for line in printed.splitlines()), printed
    assert "note       The floating joint 'f\\narmature: {j1: 5.0}\\n#' at the root" in printed
    direct = import_urdf_text(urdf.read_bytes(), str(urdf), fix_floating_root=True)
    assert load_model(out) == direct.model.spec()
    assert load_model(out).armature == ()


# -- the model name mg ---------------------------------------------------------------

@pytest.mark.parametrize("name", ["mg", "Mg", "MG", "mG"])
def test_the_model_name_mg_is_refused_with_the_reason_and_a_fix(name):
    """Its C prefixes would be mg_ and MG_, the generated code's own (the C failed to
    compile: MG_WORK_SIZE redefined, mg_system redeclared)."""
    expected = (f"name: model name '{name}' is reserved: the generated C names its own "
                "functions and constants mg_... and MG_..., which the model's would clash "
                f"with; fix: choose another model name, e.g. '{name}1'")
    with pytest.raises(ModelError) as api:
        Model(name)
    assert str(api.value) == "<api>: " + expected
    with pytest.raises(ModelError) as yaml:
        parse_model(f"name: {name}\n", "m.yaml")
    assert str(yaml.value) == "m.yaml:1: " + expected
    assert Model(name + "1").name == name + "1"


@pytest.mark.parametrize("robot, model", [("mg", "robot_mg"), ("MG_arm", "robot_MG_arm"),
                                          ("int", "int_robot")])
def test_an_imported_robot_named_mg_gets_a_valid_model_name(robot, model):
    imported = import_urdf_text(_urdf("f").replace('name="r"', f'name="{robot}"'), "r.urdf",
                                fix_floating_root=True)
    assert imported.model.name == model


# -- declaration order -----------------------------------------------------------------

def _ordered() -> Model:
    """The audit's model: a joint declared after a base, before a point."""
    return (Model("ord").add_coordinate("q").add_parameters(m=1.0, g=9.81)
            .add_base("B1", parent="E", axis=3, angle="q")
            .add_joint("K", "ball", parent="E", base="BB")
            .add_point("P", from_="O", base="B1", coordinates=[1, 0, 0])
            .add_body("b1", mass="m", G="P", base="B1", inertia=[0.1, 0.2, 0.25])
            .add_body("b2", mass="m", G="P", base="BB", inertia=[0.1, 0.2, 0.25])
            .set_gravity([0, "-g", 0]))


def _full() -> Model:
    """Every kind of entry, joints declared after the bases they hang from and before
    the points their free joint's point is measured from."""
    m = Model("full", description='all: "quotes", #hash, \\ back, */ close\nnew line \u00e9')
    m.add_coordinates("q1", "q2", "q3", "x")
    m.add_parameters({"m1": 1.3, "m2": 0.7, "L": 0.9, "g": 9.81, "k": 20.0, "c": 0.05,
                      "a": 0.1, "Ixx": 0.02, "Iyy": 0.03, "Izz": 0.04, "Ixy": 0.001,
                      "Ixz": -0.002, "Iyz": 0.0015, "tiny": 1e-5, "mu": 0.3})
    m.add_inputs("T1", "F")
    m.add_base("B1", parent="E", axis=3, angle="q1")
    m.add_base("B2", parent="B1", axis=1, angle="q2 + a*sin(pi/6)")
    m.add_base("B3", parent="B2", axis=2, angle="q3")
    m.add_base("C", parent="B3", axis=1, angle="-a")
    m.add_joint("J", "free", parent="B1", base="D", from_="P1", point="R")
    m.add_joint("K", "ball", parent="C", base="BB")
    m.add_point("P1", from_="O", base="B1", coordinates=["L", 0, "a/3"])
    m.add_point("P2", frame="F1", coordinates=["L/2", "a*cos(q2)", "x"])
    m.add_point("G3", from_="P2", base="B3", coordinates=["a", "-a/7", 0.3])
    m.add_point("A", coordinates=[0, -3, 0])
    m.add_frame("F1", point="P1", base="B2")
    m.add_body("rod1", mass="m1", G="P1", base="B1", inertia=[0, "m1*L**2/12", "m1*L**2/12"])
    m.add_body("rod2", mass="m2", G="P2", base="B2",
               inertia=[["Ixx", "Ixy", "Ixz"], ["Ixy", "Iyy", "Iyz"], ["Ixz", "Iyz", "Izz"]])
    m.add_body("rod3", mass="2*m2", G="G3", base="C",
               inertia=[[0.05, 0.001, 0.0], [0.001, 0.06, 0.002], [0.0, 0.002, 0.07]])
    m.add_body("flyer", mass="m1", G="R", base="D", inertia=["Ixx", "Iyy", "Izz"])
    m.add_body("ballb", mass="m2", G="G3", base="BB", inertia=["Izz", "Izz", "Izz"])
    m.set_gravity([0, "-g", "-tiny*t"])
    m.add_action("motor", body="rod1", point="O", base="B1", torque=[0, 0, "T1"])
    m.add_action("push", body="rod3", frame="F1", vector=[0, 0, 0, "F*cos(t)", "-c*q1_dot", 0])
    m.add_effect("spring1", "spring", point_a="A", point_b="G3", stiffness="k",
                 rest_length="L", preload="a")
    m.add_effect("hinges", "joint_damping", coordinates=["q1", "q2", "J_wx"], damping="c")
    m.add_effect("fr", "friction", coordinate="x", coulomb="mu*m1*g", viscous=0.01,
                 stribeck_speed=0.1)
    m.add_effect("air", "drag", body="rod2", point="P2", density=1.2, drag_coefficient="c",
                 area="a")
    m.add_effect("act", "action", body="rod2", point="P2", base="B2", torque=["T1*x", 0, 0])
    m.set_armature({"q1": "a/10", "J_wz": 0.01})
    m.set_units({"q1": "rad", "L": "m", "g": "m/s^2", "T1": "N*m"})
    return m


@pytest.mark.parametrize("make", [_ordered, _full], ids=["audit", "full"])
def test_a_model_built_in_any_order_reads_back_to_the_same_spec_and_c(make):
    """The YAML reader declares joints first; a spec is ordered the same way however it
    was built, so the file, the API and from_spec give one spec, one cache entry and
    bit-identical results."""
    model = make()
    spec = model.spec()
    again = parse_model(model.to_yaml())
    assert again == spec
    assert Model.from_spec(spec).spec() == spec
    assert [b.name for b in again.bases] == [b.name for b in spec.bases]
    assert [p.name for p in again.points] == [p.name for p in spec.points]
    a, b = modelgen.load(spec), modelgen.load(again)
    assert a.path == b.path
    rng = np.random.default_rng(3)
    for _ in range(5):
        x = rng.normal(size=a.nx)
        for quaternion in a.quaternions:
            x[list(quaternion)] /= np.linalg.norm(x[list(quaternion)])
        u = rng.normal(size=len(a.inputs))
        assert np.array_equal(a.rhs(0.3, x, u), b.rhs(0.3, x, u))


# -- API inputs that raised bare Python errors -------------------------------------------

def _m() -> Model:
    return Model("m").add_coordinate("q").add_parameter("L", 1.0)


@pytest.mark.parametrize("call, phrase", [
    (lambda: _m().add_parameter("a", 10**400), "the default of parameter 'a' overflows a double"),
    (lambda: _m().add_parameter("a", -10**5000), "overflows a double"),
    (lambda: _m().add_parameter("a", Fraction(10**500, 3)), "overflows a double"),
    (lambda: _m().add_parameter("a", Fraction(1, 10**500)), "is too small for a double"),
    (lambda: _m().add_base("B", parent="E", axis=1, angle=10**5000),
     "a number in the expression has more than 400 digits"),
    (lambda: _m().add_base("B", parent="E", axis=1, angle=sympy.Integer(10**5000)),
     "a number in the expression has more than 3913 digits; fix: use fewer significant"),
    (lambda: _m().add_base("B", parent="E", axis=1, angle=sympy.Rational(1, 10**5000) * 3),
     "more than 3913 digits"),
    (lambda: _m().add_base("B", parent=10**5000, axis=1, angle=0),
     "expected a base name but got an integer of about 5000 digits"),
    (lambda: _m().add_joint("J", ["ball"], parent="E", base="D"),
     "joints.J.type: unknown joint kind a list of 1 item"),
    (lambda: _m().add_joint("J", {"ball": 1}, parent="E", base="D"), "unknown joint kind"),
    (lambda: _m().set_units(["q"]),
     "units: set_units() takes a mapping (a dict) but got a list of 1 item; "
     "fix: pass a dict, e.g. set_units({'L': 'm'})"),
    (lambda: _m().set_units("m"), "set_units() takes a mapping"),
    (lambda: _m().set_armature(["q"]), "armature: set_armature() takes a mapping"),
    (lambda: _m().set_armature(3), "set_armature() takes a mapping (a dict) but got the number 3"),
    (lambda: _m().add_parameters([1]), "parameters: add_parameters() takes a mapping"),
    (lambda: _m().add_parameters(np.array([1.0])), "add_parameters() takes a mapping"),
])
def test_hostile_api_inputs_are_model_errors(call, phrase):
    with pytest.raises(ModelError) as caught:
        call()
    assert phrase in str(caught.value)


def test_set_units_none_removes_the_units_as_yaml_null_does():
    m = _m().set_units({"L": "m"}).set_units(None)
    assert m.spec().units == () == parse_model("name: m\nunits: null\n").units


# -- what is accepted can be written and read back -------------------------------------

def test_an_expression_sympy_writes_out_too_long_is_refused_when_given():
    """sympy multiplies 7 into the sum: 9,907 characters become 15,405, which the
    writer would write and the reader refuse."""
    terms, i = [], 2
    while len("7*(" + "+".join(terms) + ")") < 9900:
        terms.append(f"q**{i}")
        i += 1
    text = "7*(" + "+".join(terms) + ")"
    assert len(text) <= 10_000
    with pytest.raises(ModelError, match="the expression is 15405 characters long as sympy "
                       "writes it"):
        Model("m").add_coordinate("q").add_point("P", coordinates=[text, 0, 0])
    short = "7*(" + "+".join(terms[:600]) + ")"
    m = Model("m").add_coordinate("q").add_point("P", coordinates=[short, 0, 0])
    assert parse_model(m.to_yaml()) == m.spec()


@pytest.mark.parametrize("description", [
    "emoji \U0001F600 here", "\U0010FFFF", "e\u0301 \u00e9 \u2028 \x85 \ufffe", "del\x7f",
    "a\\ud83d\\ude00 (written, not a character)", "lone \ud800 surrogate", "tab\tnul\x00"])
def test_a_description_with_any_characters_reads_back_the_same(description):
    m = Model("m", description=description)
    assert parse_model(m.to_yaml()).description == description


# -- the acceleration symbols of the symbolic queries ---------------------------------------

@pytest.mark.parametrize("build, phrase", [
    (lambda: Model("m").add_coordinate("q").add_parameter("q_ddot", 2.0),
     "'q_ddot' is the acceleration of coordinate 'q'"),
    (lambda: Model("m").add_parameter("q_ddot", 2.0).add_coordinate("q"),
     "the acceleration of coordinate 'q' would be 'q_ddot', which is already declared as a "
     "parameter"),
    (lambda: Model("m").add_coordinate("q").add_input("q_ddot"), "acceleration of coordinate"),
    (lambda: Model("m").add_joint("J", "ball", parent="E", base="B").add_parameter("J_wx_dot", 1),
     "'J_wx_dot' is the acceleration of joint speed 'J_wx'"),
    (lambda: Model("m").add_parameter("J_wy_dot", 1).add_joint("J", "ball", parent="E", base="B"),
     "the acceleration of joint speed 'J_wy' would be 'J_wy_dot'"),
    (lambda: Model("m").add_coordinate("q").add_parameter("q_dot", 2.0),
     "'q_dot' is the speed of coordinate 'q'"),
    (lambda: Model("m").add_parameter("q_dot", 2.0).add_coordinate("q"),
     "the speed of coordinate 'q' would be 'q_dot'"),
])
def test_the_names_of_speeds_and_accelerations_are_reserved(build, phrase):
    """Mechanism.acceleration writes q_ddot for coordinate q: a parameter q_ddot was the
    same symbol (acceleration of P = [q_ddot*q, 0, 0] came out as [q_ddot**2, 0, 0])."""
    with pytest.raises(ModelError) as caught:
        build()
    assert phrase in str(caught.value)
    assert "fix: rename" in str(caught.value)


def test_mechanism_takes_a_model_or_refuses_with_a_type_error():
    m = (Model("m").add_coordinate("q").add_parameter("c", 2.0)
         .add_point("P", coordinates=["c*q", 0, 0]).add_body("b", mass=1, G="P", base="E"))
    mechanism = Mechanism(m)
    assert mechanism.spec == m.spec()
    assert list(mechanism.acceleration("P")) == [symbol("c") * symbol("q_ddot"), 0, 0]
    with pytest.raises(TypeError, match="Mechanism takes a ModelSpec or a Model, not str"):
        Mechanism("m.yaml")


# -- messages in the API's own words -------------------------------------------------------

@pytest.mark.parametrize("call, expected", [
    (lambda: _m().add_point("P", base="E", coordinates=[0, 0, 0]),
     "<api>: points.P: missing argument from_= (needed with base=); fix: add from_=, or use "
     "frame= instead of base="),
    (lambda: _m().add_point("P", from_="O", coordinates=[0, 0, 0]),
     "<api>: points.P: missing argument base= (needed with from_=); fix: add base=, or use "
     "frame= instead of from_="),
    (lambda: _m().add_point("P", frame="F", from_="O", coordinates=[0, 0, 0]),
     "<api>: points.P.frame: frame= cannot be combined with from_= or base=; fix: give either "
     "frame= or from_= and base="),
    (lambda: _m().add_joint("K", "ball", parent="E", base="D", from_="O"),
     "<api>: joints.K.from: a ball joint has no from_=; fix: remove it, or make the joint "
     "kind='free'"),
    (lambda: _m().add_joint("K", "free", parent="E", base="D"),
     "<api>: joints.K: missing argument point=; fix: a free joint makes a point: add "
     "point='<new point name>'"),
    (lambda: _m().add_parameter("a", "1e-400"),
     "<api>: parameters.a: the default of parameter 'a' is too small for a double (it would "
     "be 0); fix: use a magnitude of at least 5e-324, or 0"),
    (lambda: _m().add_parameter("a", "1e400"),
     "<api>: parameters.a: the default of parameter 'a' overflows a double (its magnitude is "
     "above 1.8e308); fix: write a number of magnitude at most 1.7e308"),
])
def test_api_messages_use_the_python_spelling(call, expected):
    with pytest.raises(ModelError) as caught:
        call()
    assert str(caught.value) == expected


@pytest.mark.parametrize("text, expected", [
    ("points: {P: {base: E, coordinates: [0, 0, 0]}}",
     "m.yaml:2: points.P: missing required key 'from' (needed with 'base'); fix: add 'from', "
     "or use 'frame' instead of 'base'"),
    ("joints: {K: {type: ball, parent: E, base: D, from: O}}",
     "m.yaml:2: joints.K.from: a ball joint has no 'from'; fix: remove it, or make the joint "
     "'type: free'"),
    ("parameters: {a: 1.0e-400}",
     "m.yaml:2: parameters.a: the number 1.0e-400 is too small for a double (it would be 0); "
     "fix: use a magnitude of at least 5e-324, or 0"),
    ("parameters: {a: 1.0e+400}",
     "m.yaml:2: parameters.a: the number 1.0e+400 overflows a double (its magnitude is above "
     "1.8e308); fix: write a number of magnitude at most 1.7e308"),
    ("parameters: {a: 1e-400}",
     "m.yaml:2: parameters.a: the default of parameter 'a' is too small for a double (it "
     "would be 0); fix: use a magnitude of at least 5e-324, or 0"),
])
def test_model_file_messages_keep_the_yaml_spelling_and_agree_on_numbers(text, expected):
    with pytest.raises(ModelError) as caught:
        parse_model("name: m\n" + text + "\n", "m.yaml")
    assert str(caught.value) == expected


@pytest.mark.parametrize("method", ["add_coordinates", "add_inputs"])
def test_several_names_from_a_mapping_are_refused(method):
    # a dict's keys were taken as the names and its values dropped unread
    with pytest.raises(ModelError, match=rf"expected names but got a mapping; fix: pass "
                                         rf"names, e.g. {method}\('a', 'b'\)"):
        getattr(Model("m"), method)({"a": 1.0})
    spec = getattr(Model("m"), method)(("a", "b")).spec()
    assert (spec.coordinates if method == "add_coordinates" else spec.inputs) == ("a", "b")
