"""Scene edges: names the results already use, mixed input interpolation, hostile
numbers, a model path that is no model, scene detection, the kinematics reference,
the command line's overrides, a scene named like its model, stale plots."""
from __future__ import annotations

import csv
import os
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from conftest import MODELS, ROOT, SCENES

import modelgen
from modelgen.cli import main
from modelgen.errors import ArgumentValueError, ModelError
from modelgen.model import is_scene_file, is_scene_text
from modelgen.model.messages import describe
from modelgen.model.records import InputSignal
from modelgen.model.scene import KINEMATICS_REFERENCES, parse_scene
from modelgen.sim.scene import (_input_samples, _scene_times, read_card, remove_stale_products,
                                with_settings)

# one line per key, so that replacing a value keeps every line number
BASE = {
    "scene": "dp",
    "model": "double_pendulum.yaml",
    "effects": "[gravity, motor]",
    "initial": "{q1: 1.0, q2: 0.5, q1_dot: 0.0, q2_dot: 0.0}",
    "time": "{end: 1.0, sample: 0.01}",
    "integrator": "{method: rk4, step: 0.001}",
    "outputs": "{tip: {position: P1}}",
}


def scene_text(**changes) -> str:
    return "".join(f"{key}: {value}\n" for key, value in {**BASE, **changes}.items()
                   if value is not None)


def error(base_dir=MODELS, **changes) -> str:
    with pytest.raises(ModelError) as info:
        parse_scene(scene_text(**changes), source="s.yaml", base_dir=base_dir)
    return str(info.value)


# -- 1: an output named like a column the results already have ------------------------------

@pytest.mark.parametrize("outputs, expected", [
    ("{kinetic: {energy: kinetic}}",
     "s.yaml:7: outputs.kinetic: output name 'kinetic' is also a column of the recorded "
     "energies: the results' columns and res['kinetic'] would be ambiguous; fix: rename the "
     "output, e.g. 'kinetic_energy' (t, the states q1, q2, q1_dot, q2_dot and kinetic, "
     "potential, total are taken)"),
    ("{t: {position: P1}}", "output name 't' is also the time"),
    ("{q1_dot: {velocity: P1}}", "output name 'q1_dot' is also a state of the model"),
    ("{total: {energy: total}}", "e.g. 'total_energy'"),
])
def test_an_output_named_like_the_time_a_state_or_an_energy_column_is_refused(outputs,
                                                                              expected):
    assert expected in error(outputs=outputs)


def test_the_shipped_pendulum_scene_has_no_duplicate_column_names():
    from modelgen.model.scene import load_scene
    spec = load_scene(SCENES / "simple_pendulum_swing.yaml")
    names = ["t", *spec.model.coordinates, *spec.model.speeds, "kinetic", "potential",
             "total"]
    assert not {o.name for o in spec.outputs} & set(names)


# -- 2: inputs with their own interpolations --------------------------------------------------

def _c_lookup(times, values, hold, t):
    """The C integrators' mg_inputs_at, in Python: ts[lo] <= t < ts[hi]."""
    if len(times) == 1 or t <= times[0]:
        return values[0]
    if t >= times[-1]:
        return values[-1]
    lo = int(np.searchsorted(times, t, side="right")) - 1
    a, b = values[lo], values[lo + 1]
    return a if hold else a + (b - a) * (t - times[lo]) / (times[lo + 1] - times[lo])


def test_mixed_interpolations_are_each_exact_through_the_c_lookup():
    held = InputSignal("H", times=(0.0, 0.3, 0.7), values=(1.0, -2.0, 5.0),
                       interpolation="hold")
    ramp = InputSignal("R", times=(0.1, 0.5), values=(0.0, 4.0), interpolation="linear")
    const = InputSignal("C", constant=0.25)
    times, values, how = _input_samples({"H": held, "R": ramp, "C": const}, ["R", "C", "H"])
    assert how == "linear"
    probes = [0.0, 0.05, 0.1, 0.2, 0.3, 0.45, 0.5, 0.6, 0.7, 0.9, 1.0, -1.0]
    probes += [float(np.nextafter(t, d)) for t in (0.3, 0.7, 0.1, 0.5) for d in (-1, 1)]
    for t in probes:
        u = _c_lookup(times, values, False, t)
        k = int(np.searchsorted(held.times, t, side="right")) - 1
        assert u[2] == held.values[min(max(k, 0), 2)], t          # the step exactly
        assert u[0] == pytest.approx(np.interp(t, ramp.times, ramp.values), abs=1e-15), t
        assert u[1] == 0.25


TWO_CARTS = """\
name: two_carts
coordinates: [x1, x2]
parameters: {m: 1.0}
inputs: [F1, F2]
points:
  P1: {coordinates: [x1, 0, 0]}
  P2: {coordinates: [x2, 1, 0]}
bodies:
  c1: {mass: m, G: P1, base: E}
  c2: {mass: m, G: P2, base: E}
actions:
  push1: {body: c1, point: P1, base: E, force: [F1, 0, 0]}
  push2: {body: c2, point: P2, base: E, force: [F2, 0, 0]}
"""


@pytest.fixture(scope="module")
def mixed_scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("mixed")
    (root / "two_carts.yaml").write_text(TWO_CARTS)
    (root / "mixed.yaml").write_text(
        "scene: mixed\nmodel: two_carts.yaml\neffects: [push1, push2]\n"
        "initial: {x1: 0.0, x2: 0.0, x1_dot: 0.0, x2_dot: 0.0}\n"
        "time: {end: 1.0, sample: 0.05}\nintegrator: {method: rk4, step: 0.01}\n"
        "inputs:\n"
        "  F1: {times: [0.0, 0.5], values: [0.0, 2.0], interpolation: linear}\n"
        "  F2: {times: [0.0, 0.25, 0.6], values: [1.0, -1.0, 3.0], interpolation: hold}\n")
    return modelgen.load_scene(root / "mixed.yaml", root / "build")


def test_a_scene_with_linear_and_held_inputs_runs_as_each_signal_says(mixed_scene):
    """Refused at run time before ("all sampled inputs must use the same
    interpolation"); the C run equals the same run fed by inputs_at(t)."""
    s = mixed_scene
    res = s.run()
    cm = s.model

    def feedback(t, x):
        u = s.inputs_at(t)
        return [u[name] for name in cm.inputs]

    ref = cm.simulate(s.initial_state(), (0.0, 1.0), t_eval=s.times(), method="rk4",
                      step=0.01, u=feedback)
    np.testing.assert_allclose(res.y, ref.y, rtol=1e-13, atol=1e-15)
    assert s.inputs_at(0.25)["F2"] == -1.0 and s.inputs_at(0.2499)["F2"] == 1.0


# -- 3: hostile numbers ------------------------------------------------------------------------

@pytest.mark.parametrize("changes, expected", [
    ({"integrator": "{method: rk4, step: 5.0e-324}"},
     "s.yaml:6: integrator.step: the step 5e-324 takes inf steps over the time span 1.0 s, "
     "more than the C integrator can count"),
    ({"time": "{end: 0.01, sample: 0.01}", "integrator": "{method: rk4, step: 1.0e-12}"},
     "s.yaml:6: integrator.step: the step 1e-12 takes 1e+10 steps over the time span 0.01 s, "
     "more than the 1e+09 a scene may take; fix: take larger steps, e.g. step: 1e-08, a "
     "shorter time span, or an adaptive method (method: dopri5, which picks its own steps)"),
    ({"time": "{start: -1.0e308, end: 1.0e308, sample: 1.0e300}",
      "integrator": "{method: dopri5}"},
     "s.yaml:5: time.end: the time span from -1e+308 to 1e+308 s is too long to compute"),
    ({"time": "{end: 1.0e300, sample: 1.0}", "integrator": None},
     "s.yaml:5: time: the step 0.001 takes 1e+303 steps over the time span 1e+300 s, more "
     "than the C integrator can count; fix: take a longer time.sample and integrator.step"),
    ({"time": "{end: 1.0, sample: 1.0e308}"},
     "s.yaml:5: time.sample: the sample interval 1e+308 is not a whole multiple of the step"),
])
def test_hostile_times_and_steps_are_model_errors_with_the_line(changes, expected):
    assert error(**changes).startswith(expected)


@pytest.mark.parametrize("t0, t1, dt", [(-1.0e308, 1.0e308, 1.0e300), (0.0, 1.0e6, 1.0e-6),
                                        (0.0, 1.0, 5e-324)])
def test_scene_times_refuse_too_many_samples_with_an_argument_error(t0, t1, dt):
    with pytest.raises(ArgumentValueError, match="more than max_output_mb=1000; fix: a "
                       "longer sample interval"):
        _scene_times(t0, t1, dt, 9)


def test_scene_run_refuses_too_many_samples_before_it_starts(mixed_scene):
    card = mixed_scene.card
    try:
        mixed_scene.card = replace(card, t_end=1.0e6, sample_dt=1.0e-6)
        with pytest.raises(ArgumentValueError, match=r"1e\+12 samples"):
            mixed_scene.run()
        with pytest.raises(ArgumentValueError, match="max_output_mb=0.001"):
            mixed_scene.run(max_output_mb=1e-3)
    finally:
        mixed_scene.card = card


# -- 4: a model path that is no model ----------------------------------------------------------

def test_describe_shortens_long_values_and_keeps_short_ones_whole():
    assert describe("abc") == "the string 'abc'"
    text = describe("root:x:0:0:root:/root:/bin/bash\n" * 50)
    assert len(text) < 100 and text.endswith("(1600 characters)")
    assert describe(10 ** 200).endswith("(201 characters)")


def test_a_model_that_is_no_model_names_the_scene_line_and_is_short(tmp_path):
    (tmp_path / "passwd").write_text("root:x:0:0:root:/root:/bin/bash\n" * 50)
    message = error(base_dir=tmp_path, model="passwd")
    assert message.startswith(f"s.yaml:2: model: the model file is not valid: "
                              f"{tmp_path / 'passwd'}:1: expected a mapping of model keys")
    assert len(message) < 600 and message.count("root:x") <= 2 and "characters)" in message
    (tmp_path / "bad.yaml").write_text("name: m\ncoordinates: [q]\nbases: {B: {parent: X}}\n")
    assert error(base_dir=tmp_path, model="bad.yaml").startswith(
        f"s.yaml:2: model: the model file is not valid: {tmp_path / 'bad.yaml'}:3: ")
    assert error(base_dir=tmp_path, model=".").startswith(
        f"s.yaml:2: model: '{tmp_path}' is not a model file but a folder")
    (tmp_path / "other.yaml").write_text(scene_text())
    assert error(base_dir=tmp_path, model="other.yaml").startswith(
        f"s.yaml:2: model: '{tmp_path / 'other.yaml'}' is a scene file, not a model")


# -- 5: scene detection --------------------------------------------------------------------------

@pytest.mark.parametrize("text", [
    "\ufeff" + scene_text(),
    scene_text().replace("scene:", '"scene":'),
    scene_text().replace("scene:", "'scene' :"),
    scene_text().replace("\n", "\r\n"),
    "# a scene\n---\n" + scene_text(),
    "{" + ", ".join(f"{k}: {v}" for k, v in BASE.items()) + "}\n",
    "# flow\n{\n  model: double_pendulum.yaml,\n  scene: dp, effects: [gravity, motor],\n"
    "  initial: {q1: 1.0, q2: 0.5, q1_dot: 0.0, q2_dot: 0.0},\n  time: {end: 1.0, sample: 0.01}}\n",
])
def test_scenes_are_recognised_with_a_bom_quoted_keys_or_as_flow_mappings(tmp_path, text):
    path = tmp_path / "s.yaml"
    path.write_bytes(text.encode())
    (tmp_path / "double_pendulum.yaml").write_text((MODELS / "double_pendulum.yaml").read_text())
    assert is_scene_file(path)
    from modelgen.model.scene import load_scene
    assert load_scene(path).name == "dp"


@pytest.mark.parametrize("text", [
    (MODELS / "double_pendulum.yaml").read_text(),
    "# used by the scene dp_free\nname: m\ncoordinates: [q]\n",
    "{name: m, description: a scene of sorts, coordinates: [q]}\n",
    "", "# nothing\n", "scenes: 1\n", "  scene: nested\n",
])
def test_models_and_other_text_are_not_scenes(text):
    assert not is_scene_text(text)


def test_recognising_a_block_scene_imports_no_yaml():
    """The command line asks for every file it runs; a scene run from its cached card
    reads no YAML."""
    code = (f"import sys\nfrom modelgen.model import is_scene_file\n"
            f"assert is_scene_file({str(SCENES / 'dp_free.yaml')!r})\n"
            f"print('yaml' in sys.modules)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=120)
    assert proc.stdout.strip() == "False", proc.stderr


# -- 6: the kinematics reference ---------------------------------------------------------------

def test_the_kinematics_reference_is_checked_where_the_scene_says_it():
    from modelgen.codegen.options import REFERENCES
    assert KINEMATICS_REFERENCES == REFERENCES
    assert error(kinematics="{reference: weird}") == (
        "s.yaml:8: kinematics.reference: unknown reference 'weird'; fix: did you mean "
        "'world'? write local, world or local_world_aligned")
    assert "expected a name but got the number 5" in error(kinematics="{reference: 5}")


# -- 7: the command line's overrides obey the scene file's rules -------------------------------

def _simulate(tmp_path, *flags, build=None) -> int:
    return main(["simulate", str(SCENES / "dp_free.yaml"), "--build-dir",
                 str(build or tmp_path / "b"), "-o", str(tmp_path / "out"), "--no-plot", *flags])


@pytest.mark.parametrize("flags, expected", [
    (["--dt", "0.003"], "with --dt 0.003: the sample interval 0.01 is not a whole multiple of "
     "the step 0.003; fix: samples are taken at steps: use e.g. --sample 0.009, or change "
     "--dt"),
    (["--dt", "0.5"], "with --dt 0.5: the sample interval 0.01 is not a whole multiple"),
    (["--t-end", "0.0005"], "with --t-end 0.0005: the step 0.001 is longer than the time "
     "span 0.0005 s; fix: give a step that divides --sample, e.g. --dt 5e-06"),
    (["--method", "dopri5", "--dt", "0.002"], "method dopri5 adapts its steps to rtol and "
     "atol, so a step would be ignored; fix: leave out --dt, or choose a fixed-step method, "
     "e.g. --method rk4"),
    (["--dt", "1e-10", "--t-end", "1", "--sample", "1"], "takes 1e+10 steps"),
])
def test_overrides_are_refused_as_the_scene_file_would_be(tmp_path, capsys, flags, expected):
    assert _simulate(tmp_path, *flags) == 2
    err = capsys.readouterr().err
    assert f"scene dp_free ({SCENES / 'dp_free.yaml'}) " in err and expected in err, err
    assert not (tmp_path / "b").exists()              # nothing was built


def test_with_settings_speaks_python_by_default():
    card, _ = read_card(SCENES / "dp_free.yaml")
    assert with_settings(card, step=0.002).step == 0.002
    with pytest.raises(ArgumentValueError, match="use e.g. sample_dt=0.009, or change step"):
        with_settings(card, step=0.003)
    with pytest.raises(ArgumentValueError, match="unknown scene setting 'dt'"):
        with_settings(card, dt=0.003)
    with pytest.raises(ArgumentValueError, match="is not after the scene's start 0.0"):
        with_settings(card, t_end=-1.0)


# -- 8: a scene named like its model; stale plots ----------------------------------------------

def test_a_scene_named_like_its_model_is_refused():
    assert error(scene="double_pendulum") == (
        "s.yaml:1: scene: the scene has its model's name 'double_pendulum', so its generated "
        "files would replace the model's own; fix: name the scene after what it runs, e.g. "
        "scene: s")


def test_remove_stale_products_removes_only_this_scenes_unwritten_products(tmp_path):
    for name in ("dp.png", "dp.gif", "dp.mp4", "dp.html", "dp.csv", "dp2.png", "x.gif"):
        (tmp_path / name).write_text("old")
    removed = remove_stale_products(tmp_path, "dp", (".png",))
    assert sorted(p.name for p in removed) == ["dp.gif", "dp.html", "dp.mp4"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dp.csv", "dp.png", "dp2.png", "x.gif"]
    assert remove_stale_products(tmp_path / "missing", "dp", ()) == []


def test_a_run_without_plots_leaves_no_plot_of_an_earlier_run(tmp_path, build_root):
    out = tmp_path / "out"
    out.mkdir()
    for name in ("dp_free.png", "dp_free.gif", "dp_free.html", "notes.png"):
        (out / name).write_text("an earlier run")
    assert _simulate(tmp_path, "--t-end", "0.05", build=build_root / "edges") == 0
    assert sorted(p.name for p in out.iterdir()) == ["dp_free.csv", "dp_free.npz", "notes.png"]
    with open(out / "dp_free.csv", newline="") as fh:
        header = next(csv.reader(fh))
    assert len(header) == len(set(header))
