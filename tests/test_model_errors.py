"""Every kind of model error, with its exact message (file, line, key, name, fix)."""
from __future__ import annotations

import pytest

from modelgen.errors import ModelError, ModelgenError
from modelgen.model.api import Model, load_model, parse_model

# lines 1-5; the snippets below start at line 6
HEADER = """name: m
coordinates: [q1, q2]
parameters: {m1: 1.0, l1: 1.0, g: 9.81}
inputs: [T1]
bodies: {rod: {mass: m1, G: O, base: E}}
"""


def error(snippet: str, header: str = HEADER) -> ModelError:
    with pytest.raises(ModelError) as info:
        parse_model(header + snippet, source="m.yaml")
    return info.value


def message(snippet: str, header: str = HEADER) -> str:
    return str(error(snippet, header))


def api_message(call) -> str:
    with pytest.raises(ModelError) as info:
        call()
    return str(info.value)


# -- unknown references ------------------------------------------------------------------

def test_unknown_base_lists_known_bases():
    assert message("bases:\n  B1: {parent: E, axis: 3, angle: q1}\n"
                   "  B2: {parent: B9, axis: 3, angle: q2}\n") == (
        "m.yaml:8: bases.B2.parent: unknown base 'B9'; "
        "fix: declare 'B9' under 'bases' (known bases: E, B1, B2)")


def test_unknown_base_suggests_the_closest_name():
    assert message("bases:\n  Base1: {parent: E, axis: 3, angle: q1}\n"
                   "points:\n  P: {from: O, base: Bse1, coordinates: [1, 0, 0]}\n") == (
        "m.yaml:9: points.P.base: unknown base 'Bse1'; "
        "fix: did you mean 'Base1'? Otherwise declare 'Bse1' under 'bases'")


def test_reference_to_an_entity_of_another_kind():
    assert message("bases:\n  B1: {parent: rod, axis: 3, angle: q1}\n") == (
        "m.yaml:7: bases.B1.parent: 'rod' is a body, not a base; "
        "fix: name a base here (known bases: E, B1)")


def test_unknown_point():
    assert message("points:\n  P1: {from: P0, base: E, coordinates: [l1, 0, 0]}\n") == (
        "m.yaml:7: points.P1.from: unknown point 'P0'; "
        "fix: declare 'P0' under 'points' (known points: O, P1)")


def test_unknown_body():
    assert message("actions:\n  motor: {body: rod9, point: O, base: E, torque: [0, 0, T1]}\n") == (
        "m.yaml:7: actions.motor.body: unknown body 'rod9'; "
        "fix: did you mean 'rod'? Otherwise declare 'rod9' under 'bodies'")


def test_unknown_frame():
    assert message("points:\n  P1: {frame: F1, coordinates: [l1, 0, 0]}\n") == (
        "m.yaml:7: points.P1.frame: unknown frame 'F1'; "
        "fix: declare 'F1' under 'frames' (known frames: none)")


# -- cycles ---------------------------------------------------------------------------

def test_cycle_in_the_base_tree_is_named():
    assert message("bases:\n  B0: {parent: E, axis: 1, angle: q1}\n"
                   "  B1: {parent: B2, axis: 3, angle: q1}\n"
                   "  B2: {parent: B1, axis: 3, angle: q2}\n") == (
        "m.yaml:8: bases.B1.parent: the bases form a cycle: B1 -> B2 -> B1 "
        "(each base is rotated from the next); "
        "fix: make one of these bases a child of 'E' or of a base outside the cycle")


def test_base_that_is_its_own_parent_is_a_cycle():
    assert message("bases:\n  B1: {parent: B1, axis: 3, angle: q1}\n") == (
        "m.yaml:7: bases.B1.parent: the bases form a cycle: B1 -> B1 "
        "(each base is rotated from the next); "
        "fix: make one of these bases a child of 'E' or of a base outside the cycle")


def test_cycle_in_the_point_tree_is_named():
    assert message("points:\n  P1: {from: P3, base: E, coordinates: [1, 0, 0]}\n"
                   "  P2: {from: P1, base: E, coordinates: [1, 0, 0]}\n"
                   "  P3: {from: P2, base: E, coordinates: [1, 0, 0]}\n") == (
        "m.yaml:7: points.P1.from: the points form a cycle: P1 -> P3 -> P2 -> P1 "
        "(each point is measured from the next); "
        "fix: measure one of these points from 'O' or from a point outside the cycle")


def test_cycle_through_a_frame_is_named():
    assert message("points:\n  P1: {frame: F, coordinates: [1, 0, 0]}\n"
                   "frames:\n  F: {point: P1, base: E}\n") == (
        "m.yaml:7: points.P1.frame: the points form a cycle: P1 -> P1 "
        "(each point is measured from the next); "
        "fix: measure one of these points from 'O' or from a point outside the cycle")


# -- values ---------------------------------------------------------------------------

def test_axis_outside_one_to_three():
    assert message("bases:\n  B1: {parent: E, axis: 4, angle: q1}\n") == (
        "m.yaml:7: bases.B1.axis: axis must be 1, 2 or 3 but is the number 4; "
        "fix: use 1, 2 or 3 for the parent's x, y or z axis")


def test_vector_of_wrong_length():
    assert message("points:\n  P1:\n    from: O\n    base: E\n    coordinates: [l1, 0]\n") == (
        "m.yaml:10: points.P1.coordinates: expected 3 components but got 2; "
        "fix: write [x, y, z] (components in base 'E')")


def test_gravity_of_wrong_length():
    assert message("gravity: [0, -g]\n") == (
        "m.yaml:6: gravity: expected 3 components but got 2; "
        "fix: write [gx, gy, gz] (components in base E)")


def test_inertia_of_wrong_shape():
    assert message("bodies:\n  b: {mass: 1, G: O, base: E, inertia: [1, 2]}\n",
                   header="name: m\n\n\n\n\n") == (
        "m.yaml:7: bodies.b.inertia: expected 3 principal moments or a 3x3 matrix but got "
        "a list of 2 items; fix: write [Ixx, Iyy, Izz] (principal moments) or a 3x3 matrix "
        "[[Ixx, Ixy, Ixz], [Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]]")


def test_inertia_matrix_with_a_short_row():
    assert message("bodies:\n  b: {mass: 1, G: O, base: E, "
                   "inertia: [[1, 0, 0], [0, 1], [0, 0, 1]]}\n", header="name: m\n\n\n\n\n") == (
        "m.yaml:7: bodies.b.inertia: row 2 of the 3x3 inertia matrix is a list of 2 items, "
        "not a list of 3 items; fix: write [Ixx, Iyy, Izz] (principal moments) or a 3x3 "
        "matrix [[Ixx, Ixy, Ixz], [Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]]")


def test_action_vector_of_wrong_length():
    assert message("actions:\n  a: {body: rod, point: O, base: E, vector: [1, 2, 3, 4, 5]}\n") == (
        "m.yaml:7: actions.a.vector: expected 6 components but got 5; "
        "fix: write [Mx, My, Mz, Fx, Fy, Fz]")


def test_undefined_name_in_an_expression():
    assert message("bases:\n  B1: {parent: E, axis: 3, angle: 2*q3}\n") == (
        "m.yaml:7: bases.B1.angle: undefined name 'q3' in expression '2*q3'; "
        "fix: declare 'q3' under 'coordinates' or 'parameters'; "
        "only coordinates and parameters may be used here")


def test_undefined_name_suggests_a_close_allowed_name():
    assert message("points:\n  P: {coordinates: [l11/2, 0, 0]}\n") == (
        "m.yaml:7: points.P.coordinates[0]: undefined name 'l11' in expression 'l11/2'; "
        "fix: did you mean 'l1'? Otherwise declare 'l11' under 'coordinates' or "
        "'parameters'; only coordinates and parameters may be used here")


def test_undefined_name_in_gravity_points_to_parameters():
    assert message("gravity: [0, 0, -gravity_z]\n") == (
        "m.yaml:6: gravity[2]: undefined name 'gravity_z' in expression '-gravity_z'; "
        "fix: declare 'gravity_z' under 'parameters'; only parameters and t may be used here")


def test_speed_in_a_position_expression():
    assert message("bases:\n  B1: {parent: E, axis: 3, angle: q1 + q1_dot}\n") == (
        "m.yaml:7: bases.B1.angle: speed 'q1_dot' is not allowed in expression "
        "'q1 + q1_dot'; fix: use only coordinates and parameters here "
        "(positions and angles cannot depend on speeds, inputs or t)")


def test_input_in_a_point_coordinate():
    assert message("points:\n  P1: {coordinates: [0, T1, 0]}\n") == (
        "m.yaml:7: points.P1.coordinates[1]: input 'T1' is not allowed in expression 'T1'; "
        "fix: use only coordinates and parameters here "
        "(positions and angles cannot depend on speeds, inputs or t)")


def test_coordinate_in_gravity():
    assert message("gravity: [0, 0, -g*q1]\n") == (
        "m.yaml:6: gravity[2]: coordinate 'q1' is not allowed in expression '-g*q1'; "
        "fix: use only parameters and t here (gravity is a uniform field; use an action "
        "for forces that depend on the state or on inputs)")


def test_expression_syntax_error_gives_the_column():
    assert message("bases:\n  B1: {parent: E, axis: 3, angle: 'q1*(2 + l1'}\n") == (
        "m.yaml:7: bases.B1.angle: invalid expression: expected ')' but found the end of "
        "the expression at column 11 of 'q1*(2 + l1'; fix: close the '(' opened at column 4")


def test_expression_that_sympy_cannot_keep_in_the_grammar():
    assert message("points:\n  P1: {coordinates: [abs(exp(q1)), 0, 0]}\n") == (
        "m.yaml:7: points.P1.coordinates[0]: invalid expression: sympy rewrites the "
        "expression as 'exp(re(q1))', and re is not part of modelgen's expression grammar "
        "in 'abs(exp(q1))'; fix: simplify the expression by hand (names are not assumed "
        "real, so e.g. abs(exp(x)) becomes exp(re(x)))")


# -- names ----------------------------------------------------------------------------

@pytest.mark.parametrize("name, problem, fix", [
    ("2B", "'2B' is not a valid base name",
     "use ASCII letters, digits and '_', starting with a letter"),
    ("B-1", "'B-1' is not a valid base name",
     "use ASCII letters, digits and '_', starting with a letter"),
    ("int", "'int' is a C keyword", "rename it, e.g. 'int1'"),
    ("restrict", "'restrict' is a C keyword", "rename it, e.g. 'restrict1'"),
    ("class", "'class' is a C++ keyword", "rename it, e.g. 'class1'"),
    ("lambda", "'lambda' is a Python keyword", "rename it, e.g. 'lambda1'"),
    ("t", "'t' is reserved by modelgen (time)", "rename it, e.g. 't1'"),
    ("pi", "'pi' is reserved by modelgen (the constant pi)", "rename it, e.g. 'pi1'"),
    ("E", "'E' is reserved by modelgen (the canonical base)", "rename it, e.g. 'E1'"),
    ("O", "'O' is reserved by modelgen (the canonical point)", "rename it, e.g. 'O1'"),
    ("atan2", "'atan2' is reserved by modelgen (a function)", "rename it, e.g. 'atan21'"),
    ("_1", "'_1' starts with '_', which is reserved for generated code",
     "start the name with a letter"),
    ("__B", "'__B' starts with '_', which is reserved for generated code",
     "start the name with a letter"),
    ("MG_base", "'MG_base' starts with 'MG_', which is reserved for generated code",
     "choose a name that does not start with 'mg_'"),
])
def test_invalid_or_reserved_names(name, problem, fix):
    assert message(f"bases:\n  {name}: {{parent: E, axis: 3, angle: q1}}\n") == (
        f"m.yaml:7: bases.{name}: {problem}; fix: {fix}")


def test_name_longer_than_63_characters():
    name = "B" * 64
    assert message(f"bases:\n  {name}: {{parent: E, axis: 3, angle: q1}}\n") == (
        f"m.yaml:7: bases.{name}: base name 'BBBBBBBBBBBBBBBBBBBB...' is 64 characters long; "
        "fix: use at most 63 characters")


def test_name_equal_to_the_speed_of_a_coordinate():
    assert message("bases:\n  q2_dot: {parent: E, axis: 3, angle: q1}\n") == (
        "m.yaml:7: bases.q2_dot: 'q2_dot' is the speed of coordinate 'q2'; "
        "fix: rename it; the speed of a coordinate q is named q_dot")


def test_coordinate_whose_speed_is_already_a_name():
    assert message("", header="name: m\ncoordinates: [x_dot, x]\n") == (
        "m.yaml:2: coordinates[1]: the speed of coordinate 'x' would be 'x_dot', which is "
        "already declared as a coordinate at coordinates[0]; "
        "fix: rename coordinate 'x_dot' or coordinate 'x'")


def test_duplicate_names_across_kinds():
    assert message("frames:\n  l1: {point: O, base: E}\n") == (
        "m.yaml:7: frames.l1: duplicate name 'l1': already declared as a parameter at "
        "parameters.l1 (line 3); fix: rename one of them; coordinates, parameters, inputs, "
        "bases, points, frames, bodies and actions share one namespace")


def test_duplicate_names_within_a_list():
    assert message("", header="name: m\ncoordinates: [q1, q2, q1]\n") == (
        "m.yaml:2: coordinates[2]: duplicate name 'q1': already declared as a coordinate at "
        "coordinates[0] (line 2); fix: rename one of them; coordinates, parameters, inputs, "
        "bases, points, frames, bodies and actions share one namespace")


def test_boolean_where_a_name_is_expected():
    assert message("", header="name: m\ninputs: [u, on]\n") == (
        "m.yaml:2: inputs[1]: expected an input name but got the boolean true; "
        "fix: write an input name such as q1 (use ASCII letters, digits and '_', starting "
        "with a letter); YAML reads unquoted yes/no/on/off/true/false as booleans, "
        "so quote it")


def test_model_name_that_is_not_a_c_identifier():
    assert message("", header="name: double-pendulum\n") == (
        "m.yaml:1: name: model name 'double-pendulum' is not a valid C identifier; "
        "fix: use ASCII letters, digits and '_', starting with a letter and at most 63 "
        "characters (it prefixes every generated C function)")


def test_model_name_that_is_a_keyword():
    assert message("", header="name: double\n") == (
        "m.yaml:1: name: 'double' is a C keyword; fix: rename it, e.g. 'double1'")


def test_model_name_may_equal_a_symbol_reserved_name_but_not_an_mg_prefix():
    assert parse_model("name: E\n").name == "E"
    assert message("", header="name: mg_model\n") == (
        "m.yaml:1: name: 'mg_model' starts with 'mg_', which is reserved for generated "
        "code; fix: choose a name that does not start with 'mg_'")


# -- bodies ---------------------------------------------------------------------------

def test_negative_mass():
    assert message("bodies:\n  b: {mass: -m1/2, G: O, base: E}\n", header="name: m\n"
                   "parameters: {m1: 1.0}\n\n\n\n") == (
        "m.yaml:7: bodies.b.mass: mass of body 'b' is negative: -m1/2 = -0.5 with the "
        "default parameters; fix: give a mass >= 0")


def test_mass_that_is_not_constant():
    assert message("bodies:\n  b: {mass: m1*(1 + q1), G: O, base: E}\n",
                   header="name: m\ncoordinates: [q1]\nparameters: {m1: 1.0}\n\n\n") == (
        "m.yaml:7: bodies.b.mass: coordinate 'q1' is not allowed in expression "
        "'m1*(1 + q1)'; fix: use only parameters here (masses and inertias are constant)")


def test_inertia_depending_on_time():
    assert message("bodies:\n  b: {mass: 1, G: O, base: E, inertia: [1, 1, 1 + t]}\n",
                   header="name: m\n\n\n\n\n") == (
        "m.yaml:7: bodies.b.inertia[2]: time 't' is not allowed in expression '1 + t'; "
        "fix: use only parameters here (masses and inertias are constant)")


def test_non_symmetric_inertia():
    assert message("bodies:\n  b: {mass: 1, G: O, base: E, "
                   "inertia: [[1, 0.1, 0], [0.2, 1, 0], [0, 0, 1]]}\n",
                   header="name: m\n\n\n\n\n") == (
        "m.yaml:7: bodies.b.inertia: inertia of body 'b' is not symmetric: entry [0][1] is "
        "1/10 but entry [1][0] is 1/5; fix: make entries [0][1] and [1][0] equal")


def test_inertia_violating_the_triangle_inequality():
    assert message("bodies:\n  b: {mass: 1, G: O, base: E, inertia: [1, 1, 2.5]}\n",
                   header="name: m\n\n\n\n\n") == (
        "m.yaml:7: bodies.b.inertia: inertia of body 'b' violates the triangle inequality "
        "with the default parameters: principal moments [1, 1, 2.5], 1 + 1 < 2.5; "
        "fix: no rigid body has these moments; each principal moment must be at most the "
        "sum of the other two")


def test_inertia_with_a_negative_principal_moment():
    assert message("bodies:\n  b: {mass: 1, G: O, base: E, inertia: [I, 1, 1]}\n",
                   header="name: m\nparameters: {I: -0.5}\n\n\n\n") == (
        "m.yaml:7: bodies.b.inertia: inertia of body 'b' has a negative principal moment "
        "with the default parameters: [-0.5, 1, 1]; "
        "fix: give a positive semi-definite inertia tensor about G")


# -- structure of the file -------------------------------------------------------------

def test_missing_required_key():
    assert message("bases:\n  B1: {parent: E, angle: q1}\n") == (
        "m.yaml:7: bases.B1: missing required key 'axis'; "
        "fix: add 'axis'; a base needs parent, axis and angle")


def test_missing_model_name():
    assert message("", header="coordinates: [q]\n") == (
        "m.yaml:1: missing required key 'name'; "
        "fix: add 'name: <model name>' (a C identifier) at the top level")


def test_point_with_from_but_no_base():
    assert message("points:\n  P1: {from: O, coordinates: [1, 0, 0]}\n") == (
        "m.yaml:7: points.P1: missing required key 'base' (needed with 'from'); "
        "fix: add 'base', or use 'frame' instead of 'from'")


def test_action_without_a_point():
    assert message("actions:\n  a: {body: rod, torque: [0, 0, T1]}\n") == (
        "m.yaml:7: actions.a: missing required key 'point' (or 'frame'); "
        "fix: add 'point' and 'base', or 'frame'")


def test_frame_combined_with_from():
    assert message("points:\n  P1: {frame: F, from: O, coordinates: [0, 0, 0]}\n") == (
        "m.yaml:7: points.P1.frame: 'frame' cannot be combined with 'from' or 'base'; "
        "fix: give either 'frame' or 'from' and 'base'")


def test_vector_combined_with_torque():
    assert message("actions:\n  a: {body: rod, point: O, base: E, torque: [0, 0, 1], "
                   "vector: [0, 0, 1, 0, 0, 0]}\n") == (
        "m.yaml:7: actions.a.vector: 'vector' cannot be combined with 'torque' or 'force'; "
        "fix: give either 'vector' or 'torque' and 'force'")


def test_unknown_key_suggests_the_closest_valid_key():
    assert message("bases:\n  B1: {parent: E, axes: 3, angle: q1}\n") == (
        "m.yaml:7: bases.B1.axes: unknown key 'axes'; "
        "fix: did you mean 'axis'? valid keys: parent, axis, angle")


def test_unknown_top_level_key_suggests_the_closest_valid_key():
    assert message("gravitation: [0, 0, -g]\n") == (
        "m.yaml:6: gravitation: unknown key 'gravitation'; fix: did you mean 'gravity'? "
        "valid keys: name, description, coordinates, parameters, inputs, bases, joints, points, "
        "frames, bodies, gravity, actions, effects, armature, constraints, dependent, units, physical_inertia")


def test_unknown_key_without_a_close_match_lists_valid_keys():
    assert message("frames:\n  F: {point: O, base: E, colour: red}\n") == (
        "m.yaml:7: frames.F.colour: unknown key 'colour'; fix: valid keys: point, base")


def test_list_where_a_mapping_is_expected():
    assert message("bases:\n  B1: [E, 3, q1]\n") == (
        "m.yaml:7: bases.B1: expected a mapping but got a list of 3 items; "
        "fix: write it like 'B1: {parent: E, axis: 3, angle: q1}'")


def test_mapping_where_a_list_is_expected():
    assert message("", header="name: m\ncoordinates: {q1: 0}\n") == (
        "m.yaml:2: coordinates: expected a list of names but got a mapping; "
        "fix: write coordinates: [q1, q2]")


def test_section_of_the_wrong_type():
    assert message("bodies: [rod1]\n", header="name: m\n\n\n\n\n") == (
        "m.yaml:6: bodies: expected a mapping of body names to definitions but got a list "
        "of 1 item; fix: write one entry per line, e.g. "
        "'rod1: {mass: m1, G: G1, base: B1, inertia: [I1, I2, I3]}'")


def test_reference_of_the_wrong_type():
    assert message("frames:\n  F: {point: [O], base: E}\n") == (
        "m.yaml:7: frames.F.point: expected a point name but got a list of 1 item; "
        "fix: write the name of a point")


def test_parameter_default_that_is_not_a_number():
    assert message("", header="name: m\nparameters: {k: stiff}\n") == (
        "m.yaml:2: parameters.k: the default of parameter 'k' must be a finite real number "
        "but is the string 'stiff'; fix: write a number such as 1.0")


def test_parameter_default_that_is_not_finite():
    assert message("", header="name: m\nparameters:\n  k: .inf\n") == (
        "m.yaml:3: parameters.k: the default of parameter 'k' must be a finite real number "
        "but is the number inf; fix: write a number such as 1.0")


def test_description_that_is_not_text():
    assert message("", header="name: m\ndescription: [a, b]\n") == (
        "m.yaml:2: description: expected a string but got a list of 2 items; "
        "fix: write the description as text (quote it if needed)")


# -- YAML level -------------------------------------------------------------------------

def test_duplicate_yaml_keys_are_rejected():
    assert message("bases:\n  B1: {parent: E, axis: 3, angle: q1}\n"
                   "  B1: {parent: E, axis: 3, angle: q2}\n") == (
        "m.yaml:8: bases.B1: duplicate key 'B1' (first at line 7); "
        "fix: remove or rename one of them")


def test_duplicate_keys_inside_a_flow_mapping_are_rejected():
    assert message("bases:\n  B1: {parent: E, axis: 3, angle: q1, axis: 2}\n") == (
        "m.yaml:7: bases.B1.axis: duplicate key 'axis' (first at line 7); "
        "fix: remove or rename one of them")


def test_yaml_syntax_error_gives_the_line():
    assert message("bases:\n  B1: {parent: E, axis: 3, angle: q1\n") == (
        "m.yaml:8: invalid YAML: expected ',' or '}', but got '<stream end>' "
        "(while parsing a flow mapping); fix: correct the YAML syntax near this line")


def test_yaml_aliases_are_refused():
    assert message("gravity: &down [0, 0, -g]\nextra: *down\n") == (
        "m.yaml:7: YAML alias '*down' is not supported (aliases are refused); "
        "fix: write the value out in full")


def test_yaml_values_of_other_types_are_refused():
    assert message("", header="name: m\ndescription: 2024-05-17\n") == (
        "m.yaml:2: description: unsupported YAML value '2024-05-17' (read as timestamp); "
        "fix: quote the value")
    assert message("", header="name: m\ndescription: !!python/object:os.system x\n") == (
        "m.yaml:2: description: unsupported YAML tag 'tag:yaml.org,2002:python/object:os.system'; "
        "fix: remove the tag")


def test_non_string_keys_are_refused():
    assert message("", header="name: m\nparameters: {1: 2.0}\n") == (
        "m.yaml:2: parameters: key '1' is not a name (YAML reads it as int); "
        "fix: quote the key: \"1\"")


def test_empty_file_and_non_mapping_file():
    assert message("", header="") == (
        "m.yaml:1: the model file is empty; fix: start with 'name: <model name>' (or, for a "
        "scene, with 'scene: <name>' and 'model: <model file>')")
    assert message("", header="- a\n- b\n") == (
        "m.yaml:1: expected a mapping of model keys but got a list of 2 items; "
        "fix: start with 'name: <model name>' and use the keys name, description, "
        "coordinates, parameters, inputs, bases, joints, points, frames, bodies, gravity, actions, "
        "effects, armature, constraints, dependent, units, physical_inertia")


def test_missing_file(tmp_path):
    path = tmp_path / "absent.yaml"
    with pytest.raises(ModelError) as info:
        load_model(path)
    assert str(info.value) == (f"{path}: cannot read the model file: No such file or "
                               "directory; fix: check the path")


def test_error_attributes_are_kept_for_programs():
    exc = error("bases:\n  B1: {parent: E, axis: 0, angle: q1}\n")
    assert (exc.file, exc.line, exc.key) == ("m.yaml", 7, "bases.B1.axis")
    assert isinstance(exc, ModelgenError)


# -- the Python API ----------------------------------------------------------------------

def test_api_errors_name_the_api_and_the_key():
    m = Model("m").add_coordinate("q1")
    assert api_message(lambda: m.add_base("B1", parent="E", axis=3, angle="q1*q9")) == (
        "<api>: bases.B1.angle: undefined name 'q9' in expression 'q1*q9'; "
        "fix: declare 'q9' under 'coordinates' or 'parameters'; "
        "only coordinates and parameters may be used here")


def test_api_unknown_reference_is_reported_by_spec():
    m = Model("m").add_coordinate("q1").add_base("B2", parent="B1", axis=3, angle="q1")
    assert api_message(m.spec) == (
        "<api>: bases.B2.parent: unknown base 'B1'; "
        "fix: declare 'B1' under 'bases' (known bases: E, B2)")


def test_api_rejects_an_invalid_model_name():
    assert api_message(lambda: Model("my model")) == (
        "<api>: name: model name 'my model' is not a valid C identifier; "
        "fix: use ASCII letters, digits and '_', starting with a letter and at most 63 "
        "characters (it prefixes every generated C function)")


def test_api_rejects_expressions_outside_the_grammar():
    import sympy
    from modelgen.model.spec import symbol
    m = Model("m").add_coordinate("q")
    assert api_message(lambda: m.add_base(
        "B", parent="E", axis=1, angle=sympy.Function("f")(symbol("q")))) == (
        "<api>: bases.B.angle: invalid expression: cannot write 'f(q)': f is not part of "
        "modelgen's expression grammar; fix: use numbers, names, + - * / **, parentheses "
        "and the functions sin cos tan asin acos atan atan2 sinh cosh tanh exp log sqrt "
        "abs sign")


def test_failed_api_call_leaves_the_model_unchanged():
    m = Model("m").add_coordinate("q1").add_parameter("L", 1.0)
    before = m.spec()
    with pytest.raises(ModelError):
        m.add_coordinates("q2", "q3", "while")   # the third name is a keyword
    with pytest.raises(ModelError):
        m.add_parameters({"a": 1.0, "b": float("nan")})
    with pytest.raises(ModelError):
        m.add_point("P", parent="O", base="E", coordinates=["L", 0])
    with pytest.raises(ModelError):
        m.add_body("b", mass="L", G="O", base="E", inertia=[1, 1, 3])
    assert m.spec() == before
    # the names of the failed calls are still free
    m.add_coordinates("q2", "q3").add_parameter("a", 2.0)
    m.add_point("P", parent="O", base="E", coordinates=["L", 0, 0])
    assert m.spec().coordinates == ("q1", "q2", "q3")


def test_failed_load_leaves_nothing_behind():
    with pytest.raises(ModelError):
        parse_model("name: m\ncoordinates: [q]\nbases: {B: {parent: X, axis: 3, angle: q}}\n")
    # a later, valid load is unaffected by the failed one
    assert parse_model("name: m\ncoordinates: [q]\n").coordinates == ("q",)


def test_principal_moments_are_the_eigenvalues_numpy_gives_bit_for_bit():
    """A diagonal inertia is checked without numpy; its scaled eigenvalues are the
    ones ``numpy.linalg.eigvalsh`` returns, to the last bit, at every scale."""
    import numpy as np

    from modelgen.model.inertia import _scaled_eigenvalues
    rng = np.random.default_rng(7)
    for _ in range(2000):
        moments = [float(v) for v in rng.uniform(-1, 1, 3) * 10.0 ** rng.integers(-300, 300, 3)]
        moments[rng.integers(3)] = rng.choice([0.0, -0.0, moments[0]])
        values = [[moments[i] if i == j else 0.0 for j in range(3)] for i in range(3)]
        matrix = np.array(values)
        scale = float(np.max(np.abs(matrix))) or 1.0
        d, got_scale = _scaled_eigenvalues(values)
        assert got_scale == scale
        assert [repr(v) for v in d] == [repr(float(v)) for v in np.linalg.eigvalsh(matrix / scale)]
    full = [[2.0, 0.5, 0.0], [0.5, 1.0, 0.25], [0.0, 0.25, 1.5]]
    d, scale = _scaled_eigenvalues(full)
    assert np.allclose(np.array(d) * scale, np.linalg.eigvalsh(np.array(full)), rtol=1e-14)
