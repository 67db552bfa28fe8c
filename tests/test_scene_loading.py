"""Scenes: the shipped scene files, the reduced model, and every scene error's message."""
from __future__ import annotations

import math
import os
from dataclasses import replace
from pathlib import Path

import pytest

from modelgen.errors import ModelError
from modelgen.model.api import load_model, parse_model, spec_to_yaml
from modelgen.model.scene import load_scene, parse_scene
from modelgen.model.spec import InputSignal, JointDampingEffect, OutputSpec, symbol

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
SCENE_FILES = sorted((MODELS / "scenes").glob("*.yaml"))

# one line per key, so that replacing a value keeps every line number
BASE = {
    "scene": "dp",
    "model": "double_pendulum.yaml",
    "add_parameters": "{c: 0.05}",
    "add_effects": "{hinge_damping: {type: joint_damping, coordinates: [q1, q2], damping: c}}",
    "effects": "[gravity, hinge_damping]",
    "parameters": "{m2: 2.0}",
    "initial": "{q1: 1.0, q2: 0.5, q1_dot: 0.0, q2_dot: 0.0}",
    "time": "{start: 0.0, end: 10.0, sample: 0.01}",
    "integrator": "{method: rk4, step: 0.001}",
    "inputs": "{}",
    "outputs": "{tip: {position: P1}}",
}
LINE = {key: i + 1 for i, key in enumerate(BASE)}


def scene_text(**changes) -> str:
    """BASE with some values replaced; a value of None comments the key out."""
    lines = []
    for key, value in {**BASE, **changes}.items():
        value = value if key in changes else BASE[key]
        lines.append(f"# no {key}" if value is None else f"{key}: {value}")
    return "\n".join(lines) + "\n"


def scene(**changes):
    return parse_scene(scene_text(**changes), source="s.yaml", base_dir=MODELS)


def error(**changes) -> str:
    with pytest.raises(ModelError) as info:
        scene(**changes)
    return str(info.value)


# -- the shipped scenes -------------------------------------------------------------------

def test_a_scene_is_shipped_for_every_model():
    models = {load_scene(path).full_model.name for path in SCENE_FILES}
    assert models == {path.stem for path in [*MODELS.glob("*.yaml"),
                                             *MODELS.glob("robots/*.yaml")]}
    assert {"dp_free", "dp_damped", "cart_pole_push", "spring_chain_release",
            "spring_chain_stiff", "block_friction", "arm7_damped"} <= {path.stem for path in SCENE_FILES}


@pytest.mark.parametrize("path", SCENE_FILES, ids=lambda p: p.stem)
def test_shipped_scene_loads_and_its_reduced_model_is_a_valid_model(path):
    s = load_scene(path)
    assert s.name == path.stem == s.model.name
    assert s.source == str(path)
    assert len(s.initial) == s.model.nq + s.model.n
    assert s.t_end > s.t_start and s.sample_dt > 0 and s.step > 0
    assert parse_model(spec_to_yaml(s.model)) == s.model
    assert [i.name for i in s.inputs] == list(s.full_model.inputs)


def test_dp_free_drops_the_motor_and_keeps_its_input():
    s = load_scene(MODELS / "scenes" / "dp_free.yaml")
    full = load_model(MODELS / "double_pendulum.yaml")
    assert s.full_model == full
    assert s.effects == ("gravity",)
    assert s.model == replace(full, name="dp_free", actions=(),
                              description="Double pendulum swinging freely under gravity.")
    assert s.model.inputs == ("T1",) and s.inputs == (InputSignal("T1", constant=0.0),)
    assert "c" not in s.model.parameter_names and s.stiff_effects == ()


def test_dp_damped_adds_its_effect_and_parameter():
    s = load_scene(MODELS / "scenes" / "dp_damped.yaml")
    damping = JointDampingEffect("hinge_damping", ("q1", "q2"), symbol("c"))
    assert s.model.effects == (damping,) and s.full_model.effects == (damping,)
    assert s.model.parameters[-1] == ("c", 0.05) and s.full_model.parameters[-1] == ("c", 0.05)
    assert [a.name for a in s.full_model.actions] == ["motor"] and s.model.actions == ()
    assert s.outputs[2] == OutputSpec("damping", "generalized_force",
                                      (("effect", "hinge_damping"),))


def test_stiff_and_non_smooth_effects_are_flagged_by_kind():
    stiff = {path.stem: load_scene(path).stiff_effects for path in SCENE_FILES}
    assert stiff["block_friction"] == ("friction",)
    assert stiff["spring_chain_stiff"] == ("spring1", "spring3", "spring2_stiff")
    assert stiff["dp_damped"] == () and stiff["arm7_damped"] == ()


def test_stiff_spring_is_a_million_times_stiffer():
    s = load_scene(MODELS / "scenes" / "spring_chain_stiff.yaml")
    springs = {e.name: e for e in s.model.effects}
    assert springs["spring2_stiff"].stiffness == 10**6 * springs["spring1"].stiffness
    assert "spring2" not in springs


def test_cart_pole_push_samples_its_force():
    s = load_scene(MODELS / "scenes" / "cart_pole_push.yaml")
    (force,) = s.inputs
    assert force.name == "F" and force.constant is None and force.interpolation == "linear"
    assert len(force.times) == len(force.values) and max(force.values) == 10.0


# -- the reduced model ---------------------------------------------------------------------

def test_effects_are_in_model_order_and_parameters_of_switched_off_effects_are_dropped():
    s = scene(effects="[hinge_damping, gravity]", parameters="{}")
    assert s.effects == ("gravity", "hinge_damping")
    off = scene(effects="[]", parameters="{}", outputs="{}")
    assert off.effects == () and off.model.gravity is None and off.model.effects == ()
    assert off.model.parameter_names == ("m1", "m2", "l1", "l2")      # g and c dropped
    assert off.full_model.parameter_names == ("m1", "m2", "l1", "l2", "g", "c")


def test_overrides_become_the_reduced_models_defaults():
    s = scene(parameters="{m2: 2.0, g: 1.62}")
    assert dict(s.model.parameters) == {"m1": 1.0, "m2": 2.0, "l1": 1.0, "l2": 1.0,
                                        "g": 1.62, "c": 0.05}
    assert dict(s.full_model.parameters)["m2"] == 1.0


def test_state_time_integrator_and_defaults():
    s = scene(time="{end: 2.5, sample: 0.05}", integrator=None)
    assert s.initial == (1.0, 0.5, 0.0, 0.0)
    assert (s.t_start, s.t_end, s.sample_dt, s.method, s.step) == (0.0, 2.5, 0.05, "rk4", 0.001)


def test_output_arguments_get_their_defaults():
    s = scene(outputs="{a: {position: P1}, b: {velocity: G2}, c: {orientation: B2}, "
                      "d: {angular_velocity: B2, components: B2}, E: {energy: total}, "
                      "f: {generalized_force: gravity}, g: {pose: rod1}}")
    assert [o.args for o in s.outputs] == [
        (("point", "P1"), ("from", "O"), ("base", "E")),
        (("point", "G2"), ("base", "E")),
        (("base", "B2"), ("relative_to", "E")),
        (("base", "B2"), ("relative_to", "E"), ("components", "B2")),
        (("which", "total"),),
        (("effect", "gravity"),),
        (("body", "rod1"),),
    ]


def test_inputs_constant_sampled_and_unlisted():
    s = scene(effects="[gravity, motor]", parameters="{}",
              inputs="{T1: {times: [0, 1], values: [0, 2], interpolation: hold}}")
    assert s.inputs == (InputSignal("T1", times=(0.0, 1.0), values=(0.0, 2.0),
                                    interpolation="hold"),)
    assert scene(effects="[motor]", parameters="{}", inputs="{T1: 0.5}").inputs == (
        InputSignal("T1", constant=0.5),)


# -- errors ------------------------------------------------------------------------------------

def test_unknown_model_file_names_the_path_and_suggests():
    path = os.path.normpath(MODELS / "double_pendulm.yaml")
    assert error(model="double_pendulm.yaml") == (
        f"s.yaml:2: model: model file '{path}' does not exist; "
        "fix: did you mean 'double_pendulum.yaml'?")


def test_missing_scene_file():
    with pytest.raises(ModelError) as info:
        load_scene(MODELS / "scenes" / "nothing.yaml")
    assert str(info.value) == (f"{MODELS / 'scenes' / 'nothing.yaml'}: cannot read the scene "
                               "file: No such file or directory; fix: check the path")


def test_unknown_effect_suggests_the_closest():
    assert error(effects="[gravity, hinge_dampng]") == (
        "s.yaml:5: effects[1]: unknown effect 'hinge_dampng'; fix: did you mean "
        "'hinge_damping'? effects of model 'double_pendulum': gravity, motor, hinge_damping")
    assert error(effects="[wind]") == (
        "s.yaml:5: effects[0]: unknown effect 'wind'; fix: effects of model 'double_pendulum': "
        "gravity, motor, hinge_damping (define new ones under 'add_effects')")


def test_effects_are_required_and_listed_once():
    assert error(effects=None) == (
        "s.yaml:1: missing required key 'effects'; fix: add 'effects: [gravity, motor, "
        "hinge_damping]' at the top level")
    assert error(effects="gravity") == (
        "s.yaml:5: effects: expected a list of effect names but got the string 'gravity'; "
        "fix: list the effects to switch on, e.g. effects: [gravity, motor, hinge_damping], "
        "or write effects: [] for none")
    assert error(effects="[gravity, gravity]") == (
        "s.yaml:5: effects[1]: effect 'gravity' is listed twice; fix: list each effect once")


def test_missing_initial_value_shows_the_mapping_to_write():
    assert error(initial="{q1: 1.0, q2: 0.5, q1_dot: 0.0}") == (
        "s.yaml:7: initial: missing initial value for 'q2_dot'; fix: every coordinate and "
        "speed needs one; write initial: {q1: 1.0, q2: 0.5, q1_dot: 0.0, q2_dot: 0.0}")
    assert error(initial="{q1: 1.0}") == (
        "s.yaml:7: initial: missing initial values for 'q2', 'q1_dot' and 'q2_dot'; fix: every "
        "coordinate and speed needs one; write initial: {q1: 1.0, q2: 0.0, q1_dot: 0.0, "
        "q2_dot: 0.0}")
    assert error(initial=None) == (
        "s.yaml:1: missing required key 'initial'; fix: give every coordinate and speed a "
        "value, e.g. initial: {q1: 0.0, q2: 0.0, q1_dot: 0.0, q2_dot: 0.0}")


def test_unknown_state_name():
    assert error(initial="{q1: 1.0, q2: 0.5, q1_dot: 0.0, q2_dt: 0.0}") == (
        "s.yaml:7: initial.q2_dt: unknown coordinate or speed 'q2_dt'; fix: did you mean "
        "'q2_dot'? the state of model 'double_pendulum' is q1, q2, q1_dot, q2_dot")


@pytest.mark.parametrize("value, shown", [(".nan", "nan"), (".inf", "inf"), ("-.inf", "-inf")])
def test_numbers_must_be_finite(value, shown):
    assert error(initial=f"{{q1: {value}, q2: 0.5, q1_dot: 0.0, q2_dot: 0.0}}") == (
        f"s.yaml:7: initial.q1: the initial value of 'q1' must be a finite real number but is "
        f"the number {shown}; fix: write a number such as 1.0")


def test_an_initial_value_may_be_an_expression_of_numbers():
    """As a model file's expressions: the upright pendulum is where a user types pi."""
    s = scene(initial="{q1: pi - 0.1, q2: '2*pi/3', q1_dot: sqrt(2), q2_dot: '-1e-3'}")
    # evaluated exactly, then rounded once: pi - 1/10, not the double pi minus the double 0.1
    assert s.initial == (3.0415926535897935, 2.0943951023931957, math.sqrt(2), -1e-3)
    assert math.pi - 0.1 == 3.041592653589793
    assert error(initial="{q1: pi - c, q2: 0.5, q1_dot: 0.0, q2_dot: 0.0}") == (
        "s.yaml:7: initial.q1: the initial value of 'q1' must be a number or an expression "
        "of numbers; it names 'c'; fix: write a number such as 1.0 or an expression of "
        "numbers such as pi/2")
    assert "invalid expression" in error(initial="{q1: pi -, q2: 0, q1_dot: 0, q2_dot: 0}")
    assert "sqrt(...) is not a finite real number" in error(
        initial="{q1: sqrt(-1), q2: 0, q1_dot: 0, q2_dot: 0}")


@pytest.mark.parametrize("outputs, expected", [
    ("{tip: {position: P9}}",
     "s.yaml:11: outputs.tip.position: unknown point 'P9'; fix: points of model "
     "'double_pendulum': O, P1, G1, G2, A"),
    ("{tip: {position: G22}}",
     "s.yaml:11: outputs.tip.position: unknown point 'G22'; fix: did you mean 'G2'? points of "
     "model 'double_pendulum': O, P1, G1, G2, A"),
    ("{tip: {position: P1, base: B22}}",
     "s.yaml:11: outputs.tip.base: unknown base 'B22'; fix: did you mean 'B2'? bases of model "
     "'double_pendulum': E, B1, B2"),
    ("{tip: {position: rod1}}",
     "s.yaml:11: outputs.tip.position: 'rod1' is a body, not a point; fix: name a point here "
     "(points of model 'double_pendulum': O, P1, G1, G2, A)"),
    ("{p: {pose: rd2}}",
     "s.yaml:11: outputs.p.pose: unknown body 'rd2'; fix: did you mean 'rod2'? bodies of "
     "model 'double_pendulum': rod1, rod2"),
    ("{tip: {positon: P1}}",
     "s.yaml:11: outputs.tip.positon: unknown output kind 'positon'; fix: did you mean "
     "'position'? output kinds: position, velocity, orientation, angular_velocity, energy, "
     "generalized_force, power, pose, constraint_force"),
    ("{tip: {position: P1, velocity: P1}}",
     "s.yaml:11: outputs.tip.velocity: output 'tip' has two kinds, 'position' and 'velocity'; "
     "fix: give each output one kind (make two outputs)"),
    ("{tip: {position: P1, frm: O}}",
     "s.yaml:11: outputs.tip.frm: unknown key 'frm' for a position output; fix: did you mean "
     "'from'? a position output takes position, from, base"),
    ("{e: {energy: totl}}",
     "s.yaml:11: outputs.e.energy: unknown energy 'totl'; fix: did you mean 'total'? write "
     "kinetic, potential or total"),
    ("{f: {generalized_force: motor}}",
     "s.yaml:11: outputs.f.generalized_force: effect 'motor' is not switched on; fix: add it "
     "to 'effects', or record a switched-on effect: gravity, hinge_damping"),
    ("{f: {generalized_force: hinge}}",
     "s.yaml:11: outputs.f.generalized_force: unknown effect 'hinge'; fix: switched-on "
     "effects: gravity, hinge_damping"),
    ("{2tip: {position: P1}}",
     "s.yaml:11: outputs.2tip: '2tip' is not a valid output name; fix: use ASCII letters, "
     "digits and '_', starting with a letter"),
])
def test_output_errors(outputs, expected):
    assert error(outputs=outputs) == expected


def test_potential_energy_is_refused_with_gravity_in_a_moving_base():
    text = scene_text(add_effects="{field: {type: gravity, vector: [0, -1, 0], base: B1}}",
                      effects="[field]", parameters="{}", add_parameters=None,
                      outputs="{e: {energy: potential}}")
    with pytest.raises(ModelError) as info:
        parse_scene(text, "s.yaml", MODELS)
    assert str(info.value) == (
        "s.yaml:11: outputs.e.energy: the potential energy leaves out gravity effect 'field' "
        "(its base is 'B1', not E); fix: give that gravity vector in base E, or record "
        "energy: kinetic")


@pytest.mark.parametrize("changes, expected", [
    ({"time": "{start: 1.0, end: 1.0, sample: 0.01}"},
     "s.yaml:8: time.end: the end time 1.0 is not after the start time 1.0; "
     "fix: make end greater than start"),
    ({"time": "{end: 10.0, sample: 0}"},
     "s.yaml:8: time.sample: the sample interval must be positive but is 0.0; fix: give the "
     "time between recorded samples, e.g. sample: 0.01"),
    ({"time": "{end: 10.0}"},
     "s.yaml:8: time: missing required key 'sample'; fix: write time: {start: 0.0, end: 10.0, "
     "sample: 0.01} (start defaults to 0)"),
    ({"time": "{end: 10.0, sample: 0.01, stop: 3}"},
     "s.yaml:8: time.stop: unknown key 'stop' in time; fix: valid keys: start, end, sample"),
    ({"integrator": "{method: rk4, step: -0.001}"},
     "s.yaml:9: integrator.step: the step must be positive but is -0.001; fix: give the "
     "integration step in seconds, e.g. step: 0.001"),
    ({"integrator": "{method: rk44, step: 0.001}"},
     "s.yaml:9: integrator.method: unknown integration method 'rk44'; fix: did you mean "
     "'rk4'? methods: rk4, dopri5, dop853, rodas, midpoint, gauss4 (or solve_ivp's RK45, "
     "DOP853, Radau, BDF, LSODA)"),
    ({"integrator": "{method: rk4, step: 0.003}"},
     "s.yaml:8: time.sample: the sample interval 0.01 is not a whole multiple of the step "
     "0.003; fix: samples are taken at steps: use e.g. sample: 0.009, or change "
     "integrator.step"),
])
def test_time_and_integrator_errors(changes, expected):
    assert error(**changes) == expected


@pytest.mark.parametrize("inputs, expected", [
    ("{T1: {times: [0, 1, 1], values: [0, 1, 2]}}",
     "s.yaml:10: inputs.T1.times[2]: sample times must increase, but times[2] = 1.0 follows "
     "1.0; fix: list the times in increasing order, each once"),
    ("{T1: {times: [0, 1], values: [0, 1, 2]}}",
     "s.yaml:10: inputs.T1.values: 3 values for 2 times; fix: give one value per sample time"),
    ("{T1: {times: [0, 1], values: [0, 1], interpolation: step}}",
     "s.yaml:10: inputs.T1.interpolation: unknown interpolation 'step'; fix: use linear or "
     "hold (zero-order hold)"),
    ("{T1: {times: [0, .nan], values: [0, 1]}}",
     "s.yaml:10: inputs.T1.times[1]: time 1 of input 'T1' must be a finite real number but "
     "is the number nan; fix: write a number such as 1.0"),
    ("{T11: 1.0}",
     "s.yaml:10: inputs.T11: unknown input 'T11'; fix: did you mean 'T1'? inputs of model "
     "'double_pendulum': T1"),
    ("{T1: [0, 1]}",
     "s.yaml:10: inputs.T1: expected a number or a mapping of samples but got a list of 2 "
     "items; fix: write a constant such as T1: 0.5, or T1: {times: [0.0, 1.0], values: "
     "[0.0, 2.0], interpolation: linear}"),
])
def test_input_errors(inputs, expected):
    assert error(effects="[gravity, motor]", parameters="{}", inputs=inputs) == expected


def test_input_of_a_switched_off_effect():
    assert error(inputs="{T1: 0.5}") == (
        "s.yaml:10: inputs.T1: input 'T1' is not used by the switched-on effects; "
        "fix: remove it, or switch on an effect that uses it: motor")


def test_parameter_override_errors():
    assert error(parameters="{m22: 2.0}") == (
        "s.yaml:6: parameters.m22: unknown parameter 'm22'; fix: did you mean 'm2'? parameters "
        "of model 'double_pendulum': m1, m2, l1, l2, g, c")
    assert error(effects="[gravity]", parameters="{c: 0.1}") == (
        "s.yaml:6: parameters.c: parameter 'c' is not used by the switched-on effects; "
        "fix: remove the override, or switch on an effect that uses it: hinge_damping")
    assert error(parameters="{m2: -1.0}") == (
        "s.yaml:6: parameters: with these overrides, mass of body 'rod2' is negative: m2 = "
        f"-1.0 with the default parameters ({MODELS / 'double_pendulum.yaml'}:18: "
        "bodies.rod2.mass); fix: change the overrides (give a mass >= 0)")
    assert error(parameters="{c: -1.0}") == (
        "s.yaml:6: parameters: with these overrides, damping of joint_damping 'hinge_damping' "
        f"is negative: c = -1.0 with the default parameters ({MODELS / 'double_pendulum.yaml'}"
        ": effects.hinge_damping.damping); fix: change the overrides (give a damping >= 0)")


def test_errors_in_added_effects_and_parameters_name_the_scene_file():
    assert error(add_effects="{d: {type: damper, point_a: O, point_b: P9, damping: c}}") == (
        "s.yaml:4: add_effects.d.point_b: unknown point 'P9'; fix: declare 'P9' under "
        "'points' (known points: O, P1, G1, G2, A)")
    assert error(add_parameters="{g: 1.0}") == (
        "s.yaml:3: add_parameters.g: duplicate name 'g': already declared as a parameter at "
        f"parameters.g ({MODELS / 'double_pendulum.yaml'}:4); fix: rename one of them; "
        "coordinates, parameters, inputs, bases, points, frames, bodies and actions share one "
        "namespace")
    assert error(add_effects="{motor: {type: joint_damping, coordinates: [q1], damping: c}}"
                 ) == (
        "s.yaml:4: add_effects.motor: duplicate name 'motor': already declared as an action at "
        f"actions.motor ({MODELS / 'double_pendulum.yaml'}:21); fix: rename one of them; "
        "coordinates, parameters, inputs, bases, points, frames, bodies, actions and effects "
        "share one namespace")


def test_scene_level_errors():
    assert error(scen="x") == (
        "s.yaml:12: scen: unknown key 'scen'; fix: did you mean 'scene'? valid keys: scene, "
        "description, model, add_parameters, add_effects, effects, parameters, initial, time, "
        "integrator, inputs, outputs, kinematics")
    assert error(scene="dp-1") == (
        "s.yaml:1: scene: 'dp-1' is not a valid scene name; fix: use ASCII letters, digits and "
        "'_', starting with a letter")
    assert error(model=None) == (
        "s.yaml:1: missing required key 'model'; fix: add 'model: <model file, relative to "
        "the scene file>' at the top level")
    with pytest.raises(ModelError) as info:
        parse_scene("", "s.yaml")
    assert str(info.value) == ("s.yaml:1: the scene file is empty; fix: start with 'scene: "
                               "<scene name>' and 'model: <model file>'")


@pytest.mark.parametrize("given, method", [("RK45", "dopri5"), ("DOP853", "dop853"),
                                           ("Radau", "rodas"), ("BDF", "rodas"),
                                           ("LSODA", "rodas"), ("Gauss4", "gauss4")])
def test_scene_methods_accept_solve_ivps_names(given, method):
    assert scene(integrator=f"{{method: {given}, step: 0.001}}").method == method
